#!/usr/bin/env bash
# Installs the system libraries MuJoCo's offscreen rendering needs (EGL, with OSMesa as fallback),
# on Debian/Ubuntu via apt when running as root; otherwise says what to install. Idempotent and quick
# when everything is present.
set -euo pipefail

have_lib() { ldconfig -p 2>/dev/null | grep -q "$1"; }

missing=()
have_lib 'libEGL.so.1' || missing+=(libegl1)
# Mesa's EGL vendor library and software rasteriser (llvmpipe) make EGL work without a GPU.
[ -e /usr/share/glvnd/egl_vendor.d/50_mesa.json ] || missing+=(libegl-mesa0)
ls /usr/lib/*/dri/swrast_dri.so >/dev/null 2>&1 || missing+=(libgl1-mesa-dri)
have_lib 'libOSMesa.so' || missing+=(libosmesa6)
have_lib 'libGL.so.1' || missing+=(libgl1)

if [ ${#missing[@]} -eq 0 ]; then
    exit 0
fi

if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "ipr setup: installing system packages for offscreen rendering: ${missing[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
else
    cat >&2 <<MSG
ipr setup: MuJoCo's offscreen rendering needs these system packages, which are missing:
    ${missing[*]}
Install them (Debian/Ubuntu):  sudo apt-get install ${missing[*]}
or, without root, use OSMesa from conda-forge (mesalib) and set MUJOCO_GL=osmesa.
MSG
    exit 1
fi
