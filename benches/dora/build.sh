#!/usr/bin/env bash
# Builds esgm-bench's dora peer: the `dora` CLI (PyPI's dora-rs-cli) in a venv, and the
# ping-pong node (this folder, on dora-node-api of the same version) in release.
# esgm-bench runs dora-small and dora-image when both are there (or ESGM_DORA and
# ESGM_DORA_NODE name them), and reports them as skipped otherwise.
#
#   target/bench-dora-venv/bin/dora                 the CLI and its daemon
#   target/dora/release/esgm-dora-pingpong          the node
#
# `target` is $CARGO_TARGET_DIR when set (build esgm-bench with the same one, it looks
# there), else the workspace's. Needs python3 with venv, and cargo. The first build of
# the node compiles dora's dependencies (Zenoh among them): tens of minutes on 2 cores.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
target="${CARGO_TARGET_DIR:-$root/target}"
# Keep in step with dora-node-api's version in Cargo.toml (and VERSION in
# benches/src/scenarios/dora_peer.rs): the node and the daemon speak one protocol.
version=1.1.0

venv="$target/bench-dora-venv"
if [[ "$("$venv/bin/dora" --version 2>/dev/null || true)" != "dora-cli $version" ]]; then
    python3 -m venv "$venv"
    "$venv/bin/pip" install --quiet "dora-rs-cli==$version"
fi
echo "dora CLI: $("$venv/bin/dora" --version) at $venv/bin/dora"

cargo build --release --locked --manifest-path "$here/Cargo.toml" --target-dir "$target/dora"
echo "built $target/dora/release/esgm-dora-pingpong"
