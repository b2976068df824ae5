#!/usr/bin/env bash
# Idempotent project setup: everything the build and the tests need, installed by the project's
# own files so that a fresh clone (and CI) gets the same thing as a developer's machine.
#
#   .deps/lib/   libmujoco.so (MuJoCo 3.17.0), libonnxruntime.so (ONNX Runtime 1.31.1) and
#                libOrbbecSDK.so (Orbbec SDK 2.9.3, loaded at run time by the Orbbec driver),
#                unpacked from their PyPI wheels; cargo and the binaries find them without exports
#   .venv/       Python test peers: numpy, mcap, mcap-protobuf-support, xarm-python-sdk, onnx
#                (skipped with --no-peers: `make demo` needs none of them)
#   Debian       pkg-config and libudev-dev (serial port enumeration), libzstd-dev (the MCAP
#                recordings' zstd, linked from Debian's static library instead of compiling the
#                copy zstd-sys carries: ZSTD_SYS_USE_PKG_CONFIG in .cargo/config.toml), rt-tests (cyclictest,
#                the machine's own wake-up floor that `hitl bench loop` compares with), and
#                libegl1, libegl-mesa0, libgl1-mesa-dri (the simulated camera renders with
#                MuJoCo's OpenGL renderer on an offscreen EGL device: a GPU's, or Mesa's software
#                one on a machine without), and ffmpeg (`hitl export lerobot` encodes the
#                dataset's videos with its libx264 and libx265), and gcc-avr, avr-libc,
#                binutils-avr, simavr, libsimavr-dev, libsimavrparts1 (`make firmware`: the
#                trigger box's firmware and box-sim, docs/trigger-box.md), when missing and we
#                are root
set -euo pipefail
# --no-peers: Debian packages and shared libraries only; --peers-only: the Python test peers only
# (`make test` installs them while the tests build, after `--no-peers` has run: it leaves the
# libraries the running build links against alone).
PEERS=1 LIBS=1
case "${1:-}" in
  --no-peers) PEERS=0 ;;
  --peers-only) LIBS=0 ;;
  "") ;;
  *) echo "usage: scripts/setup.sh [--no-peers | --peers-only]" >&2; exit 2 ;;
esac
cd "$(dirname "$0")/.."
ROOT=$(pwd)
MUJOCO_VERSION=3.17.0
ORT_VERSION=1.31.1
ORBBEC_WHEEL_VERSION=2.1.2   # pyorbbecsdk2 wheel; ships Orbbec SDK v2 (C API) as libOrbbecSDK.so.2.9.3
ORBBEC_SDK_VERSION=2.9.3
DEPS="$ROOT/.deps"
LIB="$DEPS/lib"
mkdir -p "$LIB" "$DEPS/wheels"

say() { printf 'setup: %s\n' "$*"; }

if [ $LIBS = 1 ]; then
# --- Debian packages the build needs -------------------------------------------------------
need_pkgs=()
for p in pkg-config libudev-dev libzstd-dev rt-tests libegl1 libegl-mesa0 libgl1-mesa-dri ffmpeg \
         gcc-avr avr-libc binutils-avr simavr libsimavr-dev libsimavrparts1; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || need_pkgs+=("$p")
done
if [ ${#need_pkgs[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then
    say "installing Debian packages: ${need_pkgs[*]}"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need_pkgs[@]}" >/dev/null
  else
    say "missing Debian packages ${need_pkgs[*]}: run 'sudo apt-get install ${need_pkgs[*]}'" >&2
    exit 1
  fi
fi

# --- Shared libraries from PyPI wheels ------------------------------------------------------
fetch_lib() { # name==version, then pairs: member inside the wheel, file name to write
  local spec=$1; shift
  local missing=0 i
  for ((i = 2; i <= $#; i += 2)); do [ -f "$LIB/${!i}" ] || missing=1; done
  if [ $missing = 0 ]; then return 0; fi
  say "fetching the $spec wheel"
  rm -rf "$DEPS/wheels/tmp" && mkdir -p "$DEPS/wheels/tmp"
  python3 -m pip download --quiet --no-deps --only-binary=:all: "$spec" -d "$DEPS/wheels/tmp"
  python3 - "$DEPS/wheels/tmp" "$LIB" "$@" <<'PY'
import sys, zipfile, glob, shutil, os
folder, lib, *pairs = sys.argv[1:]
wheel = glob.glob(folder + "/*.whl")[0]
with zipfile.ZipFile(wheel) as z:
    for member, out in zip(pairs[::2], pairs[1::2]):
        out = os.path.join(lib, out)
        os.makedirs(os.path.dirname(out), exist_ok=True)
        with z.open(member) as src, open(out + ".part", "wb") as dst:
            shutil.copyfileobj(src, dst)
        shutil.move(out + ".part", out)
PY
  rm -rf "$DEPS/wheels/tmp"
}
fetch_lib "mujoco==$MUJOCO_VERSION" "mujoco/libmujoco.so.$MUJOCO_VERSION" "libmujoco.so.$MUJOCO_VERSION"
fetch_lib "onnxruntime==$ORT_VERSION" "onnxruntime/capi/libonnxruntime.so.$ORT_VERSION" "libonnxruntime.so.$ORT_VERSION"
# The SDK's Gemini 305 support uses its frame-processor extension (extensions/ beside the library).
fetch_lib "pyorbbecsdk2==$ORBBEC_WHEEL_VERSION" \
  "pyorbbecsdk/libOrbbecSDK.so.$ORBBEC_SDK_VERSION" "libOrbbecSDK.so.$ORBBEC_SDK_VERSION" \
  "pyorbbecsdk/extensions/frameprocessor/libob_frame_processor.so" "extensions/frameprocessor/libob_frame_processor.so"
ln -sf "libmujoco.so.$MUJOCO_VERSION" "$LIB/libmujoco.so"
ln -sf "libonnxruntime.so.$ORT_VERSION" "$LIB/libonnxruntime.so"
ln -sf "libOrbbecSDK.so.$ORBBEC_SDK_VERSION" "$LIB/libOrbbecSDK.so"
ln -sf "libOrbbecSDK.so.$ORBBEC_SDK_VERSION" "$LIB/libOrbbecSDK.so.2"
fi

# --- Python venv with the test peers --------------------------------------------------------
if [ $PEERS = 0 ]; then
  say "ready (.deps/lib; the Python test peers are left to 'make test')"
  exit 0
fi
VENV="$ROOT/.venv"
STAMP="$VENV/.hitl-peers"
WANT=$(sha256sum "$ROOT/scripts/requirements-test.txt" | cut -d' ' -f1)
if [ ! -x "$VENV/bin/python" ] || [ "$(cat "$STAMP" 2>/dev/null)" != "$WANT" ]; then
  say "installing the Python test peers into .venv (scripts/requirements-test.txt)"
  [ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
  "$VENV/bin/pip" install --quiet --upgrade pip
  "$VENV/bin/pip" install --quiet -r "$ROOT/scripts/requirements-test.txt"
  echo "$WANT" > "$STAMP"
fi
say "ready (.deps/lib, .venv)"
