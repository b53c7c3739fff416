#!/usr/bin/env bash
# Install flightctl on Raspberry Pi OS (run as root from a checkout of the repository):
#
#   sudo scripts/install-pi.sh [--dry-run] [--prefix /opt/flightctl] [--source DIR] [--no-enable]
#
# Installs pigpio, enables SPI and I2C, creates the user `flightctl` (groups gpio, spi, i2c),
# installs the package in a venv under the prefix, installs the systemd units (flightctl.service and
# the pigpiod drop-in that binds pigpiod to localhost) and enables them. Every step is idempotent:
# running it again changes nothing that is already in place. --dry-run prints each step as
# "would: <command>" and changes nothing. The service is enabled but not started: it comes up
# disarmed at the next boot, or with `systemctl start flightctl`.
set -euo pipefail

PREFIX=/opt/flightctl
SOURCE=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
DRY_RUN=0
ENABLE=1
USER_NAME=flightctl
STATE_DIR=/var/lib/flightctl
UNIT_DIR=/etc/systemd/system

usage() {
    sed -n '2,11p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
}

while [ $# -gt 0 ]; do
    case "$1" in
        --dry-run) DRY_RUN=1 ;;
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
if [ -r /proc/device-tree/model ] && grep -q "Raspberry Pi 5" /proc/device-tree/model; then
    echo "install-pi.sh: warning: pigpio does not run on a Raspberry Pi 5 (the ESC output needs it)" >&2
fi

# 1. packages: pigpio (daemon and tools), Python venv support
missing=()
for pkg in pigpio python3-venv python3-dev; do
    if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
        missing+=("$pkg")
    fi
done
if [ ${#missing[@]} -gt 0 ]; then
    step "update the package lists" -- apt-get update
    step "install packages: ${missing[*]}" -- apt-get install -y "${missing[@]}"
else
    skip "packages pigpio python3-venv python3-dev installed"
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

# 4. the package with its Pi-only libraries (the `pi` extra) in a venv under the prefix (pip upgrades in place: idempotent)
if [ -x "$VENV/bin/python" ]; then
    skip "venv $VENV exists"
else
    step "create venv $VENV" -- python3 -m venv "$VENV"
fi
step "install flightctl from $SOURCE into $VENV" -- "$VENV/bin/pip" install --quiet --upgrade "$SOURCE[pi]"
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
install_unit "$SOURCE/systemd/pigpiod.service.d/flightctl.conf" "$UNIT_DIR/pigpiod.service.d/flightctl.conf"
if [ "$UNITS_CHANGED" = 1 ] || [ "$DRY_RUN" = 1 ]; then
    step "reload systemd" -- systemctl daemon-reload
fi
if [ "$ENABLE" = 1 ]; then
    step "enable pigpiod (restart to bind it to localhost)" -- systemctl enable pigpiod.service
    if [ "$UNITS_CHANGED" = 1 ] || [ "$DRY_RUN" = 1 ]; then
        step "restart pigpiod" -- systemctl restart pigpiod.service
    fi
    step "enable flightctl (starts disarmed at boot)" -- systemctl enable flightctl.service
fi

if [ "$DRY_RUN" = 1 ]; then
    echo "dry run: nothing was changed"
else
    echo "installed. Reboot if SPI or I2C were just enabled. Fly: see $PREFIX/share/pi.md"
fi
