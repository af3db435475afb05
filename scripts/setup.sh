#!/usr/bin/env bash
# Installs the Debian/Ubuntu packages Avatarm builds and renders with. Idempotent: packages
# already present are not reinstalled, and apt is not touched when nothing is missing.
set -euo pipefail
packages=(
  pkg-config g++ libudev-dev libwayland-dev libxkbcommon-dev libx11-dev libxcursor-dev libxrandr-dev libxi-dev
  mesa-vulkan-drivers libvulkan1 xvfb xauth libopenxr-loader1 libopenxr-dev libclang-dev libv4l-dev mold fonts-dejavu-core
  # The ROS 1 link: TLS for roslibrust's XML-RPC client; a ROS master and rospy (Debian's) for
  # its tests, which start a master and a simulated Sawyer node themselves.
  libssl-dev python3-rosmaster python3-rospy python3-sensor-msgs python3-std-msgs python3-genpy
  # The bag import's tests write their bags with Debian's rosbag.
  python3-rosbag python3-tf2-msgs python3-geometry-msgs
  # pip, for PyPI's MCAP reader and rosbags below.
  python3-pip
  # rosbag2's SQLite storage (avatarm import links the system's SQLite).
  libsqlite3-dev
  # The two-site tests make their TLS certificates with the openssl command.
  openssl
  # OpenH264's SIMD kernels (the h264 video codec builds without them, several times slower).
  nasm
)
# More packages a caller needs (CI: gdb and file, for a crashed process's backtraces).
# shellcheck disable=SC2206 # one word per package
packages+=(${AVATARM_EXTRA_PACKAGES:-})
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing: ${missing[*]}"
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
command -v cargo >/dev/null || {
  echo "error: cargo not found; install Rust 1.95 or newer (https://rustup.rs)" >&2
  exit 1
}
# PyPI's MCAP reader: the recording tests read each file back with it too (a second,
# independent reader); PyPI's rosbags: the rosbag2 import's tests convert their ROS 1 bags
# with it (rosbag2 written by an implementation Avatarm did not write); PyPI's cyclonedds
# (Eclipse Cyclone DDS, a ROS 2 RMW's DDS, wheels with the C library): the ROS 2 link's fake
# ros2_control arm; PyPI's eclipse-zenoh (with rosbags' CDR and REP-2016 hashes): the same
# arm, and a Zenoh router, on rmw_zenoh. Installed into Avatarm's cache folder, not the
# system's Python.
python_dir="$HOME/.cache/avatarm/python"
if ! PYTHONPATH="$python_dir" python3 -c "import mcap.reader, rosbags.convert, cyclonedds.domain, zenoh" 2>/dev/null; then
  echo "installing PyPI's mcap, rosbags, cyclonedds and eclipse-zenoh into $python_dir"
  PIP_BREAK_SYSTEM_PACKAGES=1 python3 -m pip install --quiet --upgrade --target "$python_dir" "mcap>=1.1" "rosbags==0.11.*" "cyclonedds==11.*" "eclipse-zenoh==1.10.*"
fi
