"""MPU-9250 and AK8963 register map (InvenSense RM-MPU-9250A-00, AKM AK8963 datasheet)."""

READ = 0x80                 # SPI: read = 0x80 | register

SMPLRT_DIV = 0x19
CONFIG = 0x1A               # bits 2:0 DLPF_CFG (gyro low-pass)
GYRO_CONFIG = 0x1B          # bits 4:3 GYRO_FS_SEL
ACCEL_CONFIG = 0x1C         # bits 4:3 ACCEL_FS_SEL
ACCEL_CONFIG2 = 0x1D        # bits 2:0 A_DLPF_CFG
I2C_MST_CTRL = 0x24
I2C_SLV0_ADDR = 0x25        # bit 7: read
I2C_SLV0_REG = 0x26
I2C_SLV0_CTRL = 0x27        # bit 7 enable, bits 3:0 length
ACCEL_XOUT_H = 0x3B         # 14 bytes: accel x y z, temperature, gyro x y z (big-endian int16)
EXT_SENS_DATA_00 = 0x49     # what the I2C master read from the slaves
I2C_SLV0_DO = 0x63
USER_CTRL = 0x6A
PWR_MGMT_1 = 0x6B
PWR_MGMT_2 = 0x6C
WHO_AM_I = 0x75

WHO_AM_I_MPU9250 = 0x71
H_RESET = 0x80              # PWR_MGMT_1
CLKSEL_PLL = 0x01           # PWR_MGMT_1
I2C_MST_EN = 0x20           # USER_CTRL
I2C_IF_DIS = 0x10           # USER_CTRL: SPI only
I2C_MST_400KHZ = 0x0D       # I2C_MST_CTRL
SLV_EN = 0x80               # I2C_SLV0_CTRL

# LSB per unit by the FS_SEL bits 4:3 of ACCEL_CONFIG / GYRO_CONFIG
ACCEL_LSB_PER_G = (16384.0, 8192.0, 4096.0, 2048.0)         # +-2, 4, 8, 16 g
GYRO_LSB_PER_DPS = (131.0, 65.5, 32.8, 16.4)                 # +-250, 500, 1000, 2000 deg/s
TEMP_LSB_PER_C, TEMP_OFFSET_C = 333.87, 21.0

SETUP_SPI_HZ = 1_000_000    # all registers
READ_SPI_HZ = 20_000_000    # sensor and interrupt registers only

AK8963_ADDR = 0x0C
AK_WIA = 0x00               # 0x48
AK_ST1 = 0x02
AK_HXL = 0x03               # 6 bytes little-endian x y z, then ST2
AK_ST2 = 0x09               # bit 3 HOFL: magnetic sensor overflow
AK_CNTL1 = 0x0A             # 0x16: 16-bit output, continuous measurement mode 2 (100 Hz)
AK_CNTL2 = 0x0B             # 0x01: soft reset
AK_WIA_VALUE = 0x48
AK_CNTL1_16BIT_100HZ = 0x16
AK_ST2_HOFL = 0x08
AK_TESLA_PER_LSB = 0.15e-6  # 16-bit output
MAG_READ_LEN = 7            # HXL..HZH and ST2 (reading ST2 ends the sample)
BURST_LEN = 14 + MAG_READ_LEN

# The DLPF by DLPF_CFG (register 26, gyro) and A_DLPF_CFG (register 29, accelerometer), FCHOICE_B = 0:
# (3-dB bandwidth Hz, delay s), from those registers' tables in the Register Map (RM-MPU-9250A-00 rev 1.6).
GYRO_DLPF = ((250.0, 0.97e-3), (184.0, 2.9e-3), (92.0, 3.9e-3), (41.0, 5.9e-3), (20.0, 9.9e-3),
             (10.0, 17.85e-3), (5.0, 33.48e-3), (3600.0, 0.17e-3))
ACCEL_DLPF = ((218.1, 1.88e-3), (218.1, 1.88e-3), (99.0, 2.88e-3), (44.8, 4.88e-3), (21.2, 8.87e-3),
              (10.2, 16.83e-3), (5.05, 32.48e-3), (420.0, 1.38e-3))
