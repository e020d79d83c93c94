#!/usr/bin/env bash
# Builds esgm-bench's ROS 1 peer (ros1_pingpong) from Debian's ROS 1 packages.
# esgm-bench runs ros1-small and ros1-image when benches/ros1/build/ros1_pingpong
# exists (or ESGM_ROS1_PINGPONG names it), and reports them as skipped otherwise.
#
# Needs Debian 12 (bookworm) or later; installs the packages with apt-get when run as
# root and they are missing: libroscpp-dev, libstd-msgs-dev (roscpp and the message
# headers), ros-core-dev (rosmaster, which the pair talks through), g++.
set -euo pipefail
cd "$(dirname "$0")"

packages=(libroscpp-dev libstd-msgs-dev ros-core-dev g++ pkg-config)
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

mkdir -p build
# roscpp's pkg-config file lists its dependencies (rosconsole, roscpp_serialization,
# rostime, boost); -O2 as a release build.
g++ -O2 -std=c++17 -o build/ros1_pingpong ros1_pingpong.cpp \
    $(pkg-config --cflags --libs roscpp std_msgs 2>/dev/null || echo -lroscpp -lrosconsole -lroscpp_serialization -lrostime -lboost_system)
echo "built $(pwd)/build/ros1_pingpong"
