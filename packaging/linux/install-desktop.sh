#!/usr/bin/env sh
# Desktop integration for the current user: menu entry, icons and AppStream metadata under
# ${XDG_DATA_HOME:-~/.local/share}. No root needed (the udev rule is printed, not installed).
#
#   packaging/linux/install-desktop.sh /abs/path/to/inclinometer   # what `make install-desktop` runs
#   packaging/linux/install-desktop.sh --uninstall
set -eu
HERE=$(cd "$(dirname "$0")" && pwd)
APP_ID=org.inclinometer.Inclinometer
DATA=${XDG_DATA_HOME:-$HOME/.local/share}
DESKTOP=$DATA/applications/$APP_ID.desktop
METAINFO=$DATA/metainfo/$APP_ID.metainfo.xml

refresh() {
    if command -v update-desktop-database >/dev/null 2>&1; then
        update-desktop-database -q "$DATA/applications" || true
    fi
    if command -v gtk-update-icon-cache >/dev/null 2>&1 && [ -f "$DATA/icons/hicolor/index.theme" ]; then
        gtk-update-icon-cache -q -t -f "$DATA/icons/hicolor" || true
    fi
}

if [ "${1:-}" = "--uninstall" ]; then
    rm -f "$DESKTOP" "$METAINFO"
    find "$DATA/icons/hicolor" -name "$APP_ID.*" -delete 2>/dev/null || true
    refresh
    echo "install-desktop: removed $APP_ID from $DATA"
    exit 0
fi

COMMAND=${1:?usage: install-desktop.sh /absolute/path/to/inclinometer | --uninstall}
case $COMMAND in
    /*) ;;
    *) echo "install-desktop: give an absolute path, not $COMMAND" >&2; exit 2 ;;
esac
if [ ! -x "$COMMAND" ]; then
    echo "install-desktop: $COMMAND is not an executable (run 'make bundle' or 'make run' first)" >&2
    exit 1
fi

# Exec= quoting rules of the Desktop Entry spec: double quotes around a path with spaces or
# special characters; inside them " ` $ take a backslash and a backslash takes three more
# (each escape is itself escaped once by the general string rule).
case $COMMAND in
    *[[:space:]\"\`\$\\]*)
        ESCAPED=$(printf '%s' "$COMMAND" | sed -e 's/\\/\\\\\\\\/g' -e 's/["`$]/\\\\&/g')
        EXEC="\"$ESCAPED\"" ;;
    *) EXEC=$COMMAND ;;
esac

mkdir -p "$DATA/applications" "$DATA/metainfo" "$DATA/icons"
# TryExec= is a plain string (no quoting), with only the backslash escaped.
TRYEXEC=$(printf '%s' "$COMMAND" | sed -e 's/\\/\\\\/g')
EXEC=$EXEC TRYEXEC=$TRYEXEC awk '
    /^Exec=/ { print "Exec=" ENVIRON["EXEC"]; next }
    /^TryExec=/ { print "TryExec=" ENVIRON["TRYEXEC"]; next }
    { print }
' "$HERE/$APP_ID.desktop" >"$DESKTOP"
cp "$HERE/$APP_ID.metainfo.xml" "$METAINFO"
cp -R "$HERE/icons/hicolor" "$DATA/icons/"
refresh
echo "install-desktop: 'Inclinometer' is in the applications menu (starts $COMMAND)"
echo "install-desktop: for USB access without root (ST-LINK, MCP2221A), once:"
echo "  sudo install -m 644 $HERE/60-inclinometer.rules /etc/udev/rules.d/"
echo "  sudo udevadm control --reload-rules && sudo udevadm trigger"
