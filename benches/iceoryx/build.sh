#!/usr/bin/env bash
# Builds esgm-bench's classic-iceoryx peer (iceoryx_pingpong) against Debian's iceoryx
# 2.0 C binding. esgm-bench runs iceoryx-c-small and iceoryx-c-image when
# benches/iceoryx/build/iceoryx_pingpong exists (or ESGM_ICEORYX_PINGPONG names it) and
# iox-roudi is installed, and reports them as skipped otherwise.
#
# Needs Debian 12 (bookworm) or later; installs the packages with apt-get when run as
# root and they are missing: libiceoryx-binding-c-dev (the C binding and its headers),
# iceoryx (iox-roudi, the daemon the pair talks through), gcc.
set -euo pipefail
cd "$(dirname "$0")"

packages=(libiceoryx-binding-c-dev iceoryx gcc)
missing=()
for p in "${packages[@]}"; do
    dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if ((${#missing[@]})); then
    if [[ $(id -u) -ne 0 ]]; then
        echo "missing packages: ${missing[*]} (run as root, or apt-get install them)" >&2
        exit 1
    fi
    apt-get update
    DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}"
fi

# The binding's headers live under a versioned directory (iceoryx/v2.0.3): found,
# not hard-coded, so that another Debian release's version builds too.
include=$(dirname "$(dirname "$(find /usr/include/iceoryx -path '*/iceoryx_binding_c/api.h' | sort | tail -1)")")
mkdir -p build
# -O2 as a release build.
cc -O2 -std=c11 -Wall -Wextra -I"$include" -o build/iceoryx_pingpong iceoryx_pingpong.c \
    -liceoryx_binding_c
echo "built $(pwd)/build/iceoryx_pingpong"
