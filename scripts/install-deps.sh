#!/bin/sh
# Installs the Debian packages tuile needs, only those missing (apt-get update first when needed).
set -e
PKGS="cmake make ninja-build g++ pkg-config libembree-dev libtbb-dev libxsimd-dev libopenexr-dev libcli11-dev \
libgtest-dev libbenchmark-dev zlib1g-dev libpng-dev libstb-dev libopenmpi-dev openmpi-bin \
python3 python3-dev pybind11-dev python3-numpy python3-matplotlib python3-pytest"
missing=""
for p in $PKGS; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing="$missing $p"
  fi
done
[ -z "$missing" ] && exit 0
echo "tuile: installing missing packages:$missing"
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO=sudo; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends $missing
