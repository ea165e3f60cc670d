#!/usr/bin/env bash
# Makes sure Intel Embree 3 is there for the `embree` feature (Debian's `libembree-dev`, Apache
# 2.0): `cargo build --release --features embree` then casts shadow rays with it.
set -euo pipefail
if ! ldconfig -p | grep -q 'libembree3\.so '; then
  sudo_or_not=$([ "$(id -u)" = 0 ] || echo sudo)
  $sudo_or_not apt-get install -y -q libembree-dev >/dev/null
fi
