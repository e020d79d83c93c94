#!/usr/bin/env bash
# Builds the Debian package `esgm` for this machine's architecture:
#
#   esgm-shm/apps/cli/packaging/deb.sh [OUT_DIR]        # default target/debian
#   sudo apt install ./target/debian/esgm_0.1.0_amd64.deb
#
# It holds the `esgm` command (its workers are `esgm worker …`, the same executable),
# its external subcommands `esgm-view`, `esgm-ros2` and `esgm-bridge`, the C library
# with its headers, CMake package and pkg-config file (installed by esgm-shm/cpp's
# CMake), a manual page per subcommand and bash, zsh and fish completions (generated
# by the packaged `esgm`, so they match it).
#
# It builds them in release (cargo build --release) unless ESGM_BIN_DIR names a
# directory holding them built already (the tests package their debug build).
# ESGM_PARTIAL=1 packages what that directory holds and says what it left out;
# otherwise a missing part is an error. ESGM_DEB_COMPRESSION (default xz) is
# dpkg-deb's -Z. Needs dpkg-deb, objdump (binutils: the glibc the executables need)
# and CMake; no root: files are owned by root through dpkg-deb's --root-owner-group.
set -euo pipefail
cd "$(dirname "$0")/../../../.."

out=${1:-target/debian}
version=$(sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -n1)
arch=$(dpkg --print-architecture)
bindir=${ESGM_BIN_DIR:-}
if [ -z "$bindir" ]; then
    cargo build --release --locked -p esgm-cli -p esgm-view -p esgm-ros2 -p esgm-bridge -p esgm-c
    bindir=target/release
fi
ESGM_BIN=$bindir/esgm
[ -x "$ESGM_BIN" ] || { echo "deb.sh: $ESGM_BIN is not an executable" >&2; exit 1; }
missing=()

stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
root=$stage/esgm_${version}_${arch}
install -d "$root/DEBIAN" "$root/usr/bin" "$root/usr/share/man/man1" \
    "$root/usr/share/bash-completion/completions" "$root/usr/share/zsh/vendor-completions" \
    "$root/usr/share/fish/vendor_completions.d" "$root/usr/share/doc/esgm"
install -m 0755 "$ESGM_BIN" "$root/usr/bin/esgm"
for external in esgm-view esgm-ros2 esgm-bridge; do
    if [ -x "$bindir/$external" ]; then
        install -m 0755 "$bindir/$external" "$root/usr/bin/$external"
    else
        missing+=("$external")
    fi
done
# The C library: esgm-shm/cpp's CMake installs it as `cmake --install` would into /usr.
# A `cargo build -p esgm-c` puts it in the profile's directory; a workspace's tests,
# which build it as a dependency, in its `deps`.
libdir=$bindir
if [ ! -f "$libdir/libesgm_c.so" ] && [ -f "$bindir/deps/libesgm_c.so" ]; then
    libdir=$bindir/deps
fi
if [ -f "$libdir/libesgm_c.so" ] && [ -f "$libdir/libesgm_c.a" ]; then
    multiarch=$(dpkg-architecture -qDEB_HOST_MULTIARCH 2>/dev/null || gcc -print-multiarch)
    cmake -S esgm-shm/cpp -B "$stage/cmake" -DESGM_LIBRARY_DIR="$(cd "$libdir" && pwd)" \
        -DCMAKE_INSTALL_PREFIX=/usr -DCMAKE_INSTALL_LIBDIR="lib/$multiarch" >/dev/null
    DESTDIR=$root cmake --install "$stage/cmake" >/dev/null
else
    missing+=("the C library (libesgm_c.so, libesgm_c.a, also looked for in deps/)")
fi
if [ ${#missing[@]} -gt 0 ]; then
    if [ "${ESGM_PARTIAL:-0}" = 1 ]; then
        echo "deb.sh: left out, not built in $bindir: ${missing[*]}" >&2
    else
        echo "deb.sh: not built in $bindir: ${missing[*]}" >&2
        exit 1
    fi
fi
"$root/usr/bin/esgm" man --out "$root/usr/share/man/man1" 2>/dev/null
gzip -9n "$root"/usr/share/man/man1/*.1
"$root/usr/bin/esgm" completions bash > "$root/usr/share/bash-completion/completions/esgm"
"$root/usr/bin/esgm" completions zsh > "$root/usr/share/zsh/vendor-completions/_esgm"
"$root/usr/bin/esgm" completions fish > "$root/usr/share/fish/vendor_completions.d/esgm.fish"
install -m 0644 README.md "$root/usr/share/doc/esgm/README.md"
cat > "$root/usr/share/doc/esgm/copyright" <<COPYRIGHT
Format: https://www.debian.org/doc/packaging-manuals/copyright-format/1.0/
Upstream-Name: esgm
Files: *
License: MIT or Apache-2.0
COPYRIGHT
chmod 0644 "$root/usr/share/doc/esgm/copyright"

installed_kib=$(du -sk "$root/usr" | cut -f1)
# The newest glibc symbol version the executable needs (binutils' objdump).
glibc=$(find "$root/usr" -type f \( -perm -u+x -o -name '*.so' \) -exec objdump -T {} + 2>/dev/null \
    | grep -o 'GLIBC_[0-9.]*' | sed 's/GLIBC_//' | sort -V | tail -n1)
[ -n "$glibc" ] || { echo "deb.sh: cannot tell which glibc the executables need" >&2; exit 1; }
cat > "$root/DEBIAN/control" <<CONTROL
Package: esgm
Version: $version
Architecture: $arch
Maintainer: esgm developers <esgm@localhost>
Installed-Size: $installed_kib
Depends: libc6 (>= $glibc), libgcc-s1
Section: misc
Priority: optional
Homepage: https://example.invalid/esgm
Description: knowledge processing for robots over zero-copy shared memory
 esgm turns a robot's time-stamped entity structures (images, blobs, states) into
 named trajectories with history, queried, subscribed to and constrained
 declaratively, across processes through shared memory (iceoryx2). This package
 holds the esgm command (the coordinator, queries, recordings, esgm top, the
 tutorial as esgm demo), its external subcommands (esgm view for Foxglove, esgm
 ros2 beside ROS 2, esgm bridge to other hosts over Zenoh), the C library with its
 C++ header, CMake package and pkg-config file, manual pages and completions.
CONTROL

mkdir -p "$out"
dpkg-deb --root-owner-group -Z"${ESGM_DEB_COMPRESSION:-xz}" --build "$root" "$out" >/dev/null
echo "$out/esgm_${version}_${arch}.deb"
