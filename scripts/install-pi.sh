#!/usr/bin/env bash
# Install flightctl on Raspberry Pi OS (run as root from a checkout of the repository):
#
#   sudo scripts/install-pi.sh [--dry-run] [--board pi|pi5] [--prefix /opt/flightctl] [--source DIR] [--no-enable]
#
# The board comes from the device tree's model (--board overrides it): a Raspberry Pi 5 gets the `pi5`
# board (the RP1's PWM overlay, the udev rule that gives the PWM files to group gpio, the '.[pi5]'
# extra), a Pi 3/4 the `pi` board (pigpio and its localhost-only pigpiod drop-in, the '.[pi]' extra).
# Both: SPI and I2C enabled, the user `flightctl` (groups gpio, spi, i2c), the package in a venv under
# the prefix, flightctl.service with the board's drop-in, enabled. Every step is idempotent. --dry-run
# prints each step as "would: <command>" and changes nothing. The service is enabled but not started.
set -euo pipefail

PREFIX=/opt/flightctl
SOURCE=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
DRY_RUN=0
ENABLE=1
BOARD=
USER_NAME=flightctl
STATE_DIR=/var/lib/flightctl
UNIT_DIR=/etc/systemd/system

usage() {
    sed -n '2,12p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
}

while [ $# -gt 0 ]; do
    case "$1" in
        --dry-run) DRY_RUN=1 ;;
        --board) BOARD=${2:?--board needs pi or pi5}; shift ;;
        --prefix) PREFIX=${2:?--prefix needs a directory}; shift ;;
        --source) SOURCE=${2:?--source needs a directory}; shift ;;
        --no-enable) ENABLE=0 ;;
        -h|--help) usage; exit 0 ;;
        *) echo "install-pi.sh: unknown option $1" >&2; usage >&2; exit 2 ;;
    esac
    shift
done

VENV="$PREFIX/venv"

step() {
    # step DESCRIPTION -- COMMAND...: print the step, run it unless --dry-run
    local what=$1
    shift 2
    if [ "$DRY_RUN" = 1 ]; then
        printf 'would: %s\n        %s\n' "$what" "$*"
    else
        printf '== %s\n' "$what"
        "$@"
    fi
}

skip() {
    printf 'ok: %s\n' "$1"
}

if [ "$DRY_RUN" = 0 ] && [ "$(id -u)" != 0 ]; then
    echo "install-pi.sh: run as root (sudo), or with --dry-run to see the steps" >&2
    exit 1
fi
if [ ! -f "$SOURCE/pyproject.toml" ] || [ ! -f "$SOURCE/systemd/flightctl.service" ]; then
    echo "install-pi.sh: $SOURCE is not a flightctl checkout (no pyproject.toml / systemd/)" >&2
    exit 1
fi
# the board: the RP1 I/O chip (Raspberry Pi 5, 500, Compute Module 5) or not (flightctl/boards/detect.py)
MODEL=$( { tr -d '\0' </sys/firmware/devicetree/base/model || tr -d '\0' </proc/device-tree/model; } 2>/dev/null || true)
if [ -z "$BOARD" ]; then
    case "$MODEL" in
        "Raspberry Pi 5"*|"Raspberry Pi Compute Module 5"*) BOARD=pi5 ;;    # the 500 too
        *) BOARD=pi ;;
    esac
fi
# spidev has no wheel for the Pi (aarch64, armhf): pip builds it from source, with a C compiler
# (build-essential) and Python's headers (python3-dev)
case "$BOARD" in
    pi) PACKAGES="pigpio python3-venv python3-dev build-essential" ;;
    pi5) PACKAGES="python3-venv python3-dev build-essential device-tree-compiler" ;;
    *) echo "install-pi.sh: --board $BOARD: pi (Raspberry Pi 3/4) or pi5" >&2; exit 2 ;;
esac
echo "board: $BOARD (${MODEL:-no device tree model})"
echo "packages: $PACKAGES"

# 1. packages: Python venv support and what spidev builds with; pigpio (daemon and tools, with its
# pigpiod.service) for the pi board, dtc for the pi5 overlay. pigpio comes from the Raspberry Pi archive,
# which has it up to Bookworm; Trixie and later have none (github.com/joan2937/pigpio/issues/632), and
# Debian's python3-pigpio is only the client: without pigpiod the pi board cannot fly.
if [ "$BOARD" = pi ] && ! dpkg-query -W -f='${Status}' pigpio 2>/dev/null | grep -q "install ok installed" \
        && ! apt-cache policy pigpio 2>/dev/null | grep -q "Candidate: [0-9]"; then
    # shellcheck source=/dev/null
    CODENAME=$( (. /etc/os-release && echo "${VERSION_CODENAME:-}") 2>/dev/null || true)
    echo "install-pi.sh: no pigpio package (pigpiod) for this system (${CODENAME:-unknown release}): the Raspberry Pi archive (archive.raspberrypi.org) has it up to Bookworm, not for Trixie; on a Pi 3/4 use Raspberry Pi OS Bookworm (docs/pi.md, \"Install\")" >&2
    if [ "$DRY_RUN" = 0 ]; then
        exit 1
    fi
fi
missing=()
for pkg in $PACKAGES; do
    if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
        missing+=("$pkg")
    fi
done
if [ ${#missing[@]} -gt 0 ]; then
    step "update the package lists" -- apt-get update
    step "install packages: ${missing[*]}" -- apt-get install -y "${missing[@]}"
else
    skip "packages $PACKAGES installed"
fi

# 2. SPI (the MPU-9250) and I2C (the INA219); raspi-config nonint: 0 = enable
if command -v raspi-config >/dev/null 2>&1; then
    if [ "$(raspi-config nonint get_spi 2>/dev/null || echo 1)" != 0 ]; then
        step "enable SPI" -- raspi-config nonint do_spi 0
    else
        skip "SPI enabled"
    fi
    if [ "$(raspi-config nonint get_i2c 2>/dev/null || echo 1)" != 0 ]; then
        step "enable I2C" -- raspi-config nonint do_i2c 0
    else
        skip "I2C enabled"
    fi
else
    echo "install-pi.sh: raspi-config not found: enable SPI and I2C yourself (dtparam=spi=on and dtparam=i2c_arm=on in config.txt)" >&2
    skip "SPI and I2C left as they are (no raspi-config)"
fi

# 2b. the Pi 5's PWM: the overlay that muxes the RP1's PWM0 onto GPIO 12, 13, 18, 19 (a reboot applies
# it), and the udev rule that gives the PWM files to group gpio
if [ "$BOARD" = pi5 ]; then
    BOOT=/boot/firmware
    [ -d "$BOOT/overlays" ] || BOOT=/boot
    DTBO="$BOOT/overlays/flightctl-pwm-pi5.dtbo"
    DTBO_NEW=$(mktemp)
    if [ "$DRY_RUN" = 1 ] && ! command -v dtc >/dev/null 2>&1; then
        step "compile the PWM overlay into $DTBO" -- dtc -@ -q -I dts -O dtb -o "$DTBO" "$SOURCE/scripts/flightctl-pwm-pi5-overlay.dts"
    else
        dtc -@ -q -I dts -O dtb -o "$DTBO_NEW" "$SOURCE/scripts/flightctl-pwm-pi5-overlay.dts"
        if [ -f "$DTBO" ] && cmp -s "$DTBO_NEW" "$DTBO"; then
            skip "$DTBO up to date"
        else
            step "install the PWM overlay $DTBO" -- install -D -m 0644 "$DTBO_NEW" "$DTBO"
        fi
    fi
    rm -f "$DTBO_NEW"
    if grep -qx "dtoverlay=flightctl-pwm-pi5" "$BOOT/config.txt" 2>/dev/null; then
        skip "dtoverlay=flightctl-pwm-pi5 in $BOOT/config.txt"
    else
        step "add dtoverlay=flightctl-pwm-pi5 to $BOOT/config.txt (reboot to apply)" -- \
            sh -c "printf '\n[all]\n# flightctl: the RP1 PWM0 on GPIO 12, 13, 18, 19 (the ESCs)\ndtoverlay=flightctl-pwm-pi5\n' >>'$BOOT/config.txt'"
    fi
    RULE=/etc/udev/rules.d/90-flightctl-pwm.rules
    if [ -f "$RULE" ] && cmp -s "$SOURCE/systemd/90-flightctl-pwm.rules" "$RULE"; then
        skip "$RULE up to date"
    else
        step "install $RULE (the PWM files to group gpio)" -- install -D -m 0644 "$SOURCE/systemd/90-flightctl-pwm.rules" "$RULE"
        step "apply the udev rule" -- sh -c "udevadm control --reload && udevadm trigger --subsystem-match=pwm"
    fi
fi

# 3. the service user and its groups
for group in gpio spi i2c; do
    if getent group "$group" >/dev/null; then
        skip "group $group exists"
    else
        step "create group $group" -- groupadd --system "$group"
    fi
done
if id "$USER_NAME" >/dev/null 2>&1; then
    skip "user $USER_NAME exists"
    for group in gpio spi i2c; do
        if ! id -nG "$USER_NAME" | tr ' ' '\n' | grep -qx "$group"; then
            step "add $USER_NAME to group $group" -- usermod -a -G "$group" "$USER_NAME"
        fi
    done
else
    step "create user $USER_NAME (groups gpio, spi, i2c)" -- \
        useradd --system --home-dir "$STATE_DIR" --no-create-home --shell /usr/sbin/nologin \
        --user-group --groups gpio,spi,i2c "$USER_NAME"
fi
if [ -d "$STATE_DIR/plans" ] && [ -d "$STATE_DIR/logs" ]; then
    skip "$STATE_DIR/plans and $STATE_DIR/logs exist"
    # whoever can write the plan queue can make the vehicle fly: owner and group only
    for dir in "$STATE_DIR" "$STATE_DIR/plans" "$STATE_DIR/logs"; do
        if [ -n "$(find "$dir" -maxdepth 0 -perm -o+w 2>/dev/null)" ] || [ "$(stat -c %U "$dir")" != "$USER_NAME" ]; then
            step "restrict $dir to $USER_NAME (it was writable by others or owned by someone else)" -- \
                install -d -o "$USER_NAME" -g "$USER_NAME" -m 0750 "$dir"
        fi
    done
else
    step "create $STATE_DIR/plans and $STATE_DIR/logs" -- \
        install -d -o "$USER_NAME" -g "$USER_NAME" -m 0750 "$STATE_DIR" "$STATE_DIR/plans" "$STATE_DIR/logs"
fi

# 4. the package with the board's libraries (the `pi` or `pi5` extra) in a venv under the prefix (pip upgrades in place: idempotent)
if [ -x "$VENV/bin/python" ]; then
    skip "venv $VENV exists"
else
    step "create venv $VENV" -- python3 -m venv "$VENV"
fi
step "install flightctl from $SOURCE into $VENV" -- "$VENV/bin/pip" install --quiet --upgrade "${SOURCE}[$BOARD]"
step "install docs/pi.md as $PREFIX/share/pi.md" -- install -D -m 0644 "$SOURCE/docs/pi.md" "$PREFIX/share/pi.md"

# 5. systemd units
install_unit() {
    local src=$1 dst=$2
    if [ -f "$dst" ] && cmp -s "$src" "$dst"; then
        skip "$dst up to date"
    else
        step "install $dst" -- install -D -m 0644 "$src" "$dst"
        UNITS_CHANGED=1
    fi
}
UNITS_CHANGED=0
# the unit names the prefix: carry --prefix into it
UNIT_SRC=$(mktemp)
trap 'rm -f "$UNIT_SRC"' EXIT
sed "s#/opt/flightctl#$PREFIX#g" "$SOURCE/systemd/flightctl.service" >"$UNIT_SRC"
chmod 0644 "$UNIT_SRC"
install_unit "$UNIT_SRC" "$UNIT_DIR/flightctl.service"
# the board's drop-in; the other board's is removed (a card moved from a Pi 4 to a Pi 5)
if [ "$BOARD" = pi ]; then DROPIN=pigpio.conf; OTHER=pi5.conf; else DROPIN=pi5.conf; OTHER=pigpio.conf; fi
install_unit "$SOURCE/systemd/flightctl.service.d/$DROPIN" "$UNIT_DIR/flightctl.service.d/$DROPIN"
if [ -f "$UNIT_DIR/flightctl.service.d/$OTHER" ]; then
    step "remove the other board's drop-in $UNIT_DIR/flightctl.service.d/$OTHER" -- rm -f "$UNIT_DIR/flightctl.service.d/$OTHER"
    UNITS_CHANGED=1
fi
if [ "$BOARD" = pi ]; then
    install_unit "$SOURCE/systemd/pigpiod.service.d/flightctl.conf" "$UNIT_DIR/pigpiod.service.d/flightctl.conf"
fi
if [ "$UNITS_CHANGED" = 1 ] || [ "$DRY_RUN" = 1 ]; then
    step "reload systemd" -- systemctl daemon-reload
fi
if [ "$ENABLE" = 1 ]; then
    if [ "$BOARD" = pi ]; then
        step "enable pigpiod (restart to bind it to localhost)" -- systemctl enable pigpiod.service
        if [ "$UNITS_CHANGED" = 1 ] || [ "$DRY_RUN" = 1 ]; then
            step "restart pigpiod" -- systemctl restart pigpiod.service
        fi
    fi
    step "enable flightctl (starts disarmed at boot)" -- systemctl enable flightctl.service
fi

if [ "$DRY_RUN" = 1 ]; then
    echo "dry run: nothing was changed"
else
    echo "installed ($BOARD board). Reboot if SPI, I2C or the PWM overlay were just enabled. Fly: see $PREFIX/share/pi.md"
fi
