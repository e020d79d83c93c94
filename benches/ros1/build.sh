#!/usr/bin/env bash
# Builds esgm-bench's ROS 1 peers from Debian's ROS 1 packages: ros1_pingpong and
# refsys_node. esgm-bench runs ros1-small, ros1-image and ros1-fanout-* when
# benches/ros1/build/ros1_pingpong exists (or ESGM_ROS1_PINGPONG names it), refsys-ros1
# (the Autoware reference system, a refsys_node process per node) when
# benches/ros1/build/refsys_node exists (or ESGM_ROS1_REFSYS names it), and reports them
# as skipped otherwise.
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
flags=$(pkg-config --cflags --libs roscpp std_msgs 2>/dev/null || echo -lroscpp -lrosconsole -lroscpp_serialization -lrostime -lboost_system)
for program in ros1_pingpong refsys_node; do
    g++ -O2 -std=c++17 -o "build/$program" "$program.cpp" $flags
    echo "built $(pwd)/build/$program"
done
