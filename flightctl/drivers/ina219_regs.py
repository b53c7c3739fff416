"""INA219 register map (TI SBOS448): 16-bit registers, sent most significant byte first."""

CONFIG = 0x00
SHUNT_VOLTAGE = 0x01        # signed, 10 uV per LSB
BUS_VOLTAGE = 0x02          # bits 15:3 = 4 mV per LSB; bit 1 CNVR (conversion ready); bit 0 OVF (math overflow)
POWER = 0x03
CURRENT = 0x04              # signed, current_lsb per LSB (valid once CALIBRATION is written)
CALIBRATION = 0x05          # bit 0 always reads 0

# CONFIG fields
RST = 1 << 15
BRNG_32V = 1 << 13          # bus voltage range 0..32 V (0 would be 16 V: too low for a 4S pack)
PG_SHIFT = 11               # shunt PGA gain: 0 = /1 (+-40 mV), 1 = /2 (80), 2 = /4 (160), 3 = /8 (320 mV)
BADC_SHIFT = 7              # bus ADC resolution / averaging
SADC_SHIFT = 3              # shunt ADC resolution / averaging
ADC_12BIT_8X = 0b1011       # 12 bit, 8 samples averaged: 4.26 ms per conversion
MODE_SHUNT_BUS_CONTINUOUS = 0b111
CONFIG_RESET_VALUE = 0x399F  # after power-on or RST

PG_FULL_SCALE_V = (0.040, 0.080, 0.160, 0.320)

SHUNT_LSB_V = 10e-6
BUS_LSB_V = 4e-3
BUS_SHIFT = 3
BUS_CNVR = 1 << 1
BUS_OVF = 1 << 0
CAL_NUMERATOR = 0.04096     # cal = trunc(0.04096 / (current_lsb * r_shunt))
POWER_LSB_PER_CURRENT_LSB = 20

DEFAULT_ADDRESS = 0x40
