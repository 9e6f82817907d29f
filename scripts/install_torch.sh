#!/bin/sh
# Installs torch ($TORCH) with "$PYTHON -m pip" in the build this machine can use, and says in one line which:
#   TORCH_INDEX set      -> from that index;
#   an NVIDIA GPU        -> what the configured index offers (on PyPI for Linux, the CUDA build);
#   no NVIDIA GPU        -> the CPU build: from the configured index when it serves a +cpu build, else from
#                           $TORCH_CPU_INDEX (PyTorch's CPU index), falling back to the configured index when that
#                           cannot be reached.
# NVIDIA_SMI names the probe (tests set it to a missing or a stand-in command).
set -e
: "${PYTHON:?}"
TORCH=${TORCH:-torch==2.13.0}
CPU_INDEX=${TORCH_CPU_INDEX:-https://download.pytorch.org/whl/cpu}
NVIDIA_SMI=${NVIDIA_SMI:-nvidia-smi}
pip() { "$PYTHON" -m pip "$@"; }

if [ -n "${TORCH_INDEX:-}" ]; then
    echo "torch: $TORCH from $TORCH_INDEX (TORCH_INDEX)"
    pip install -q "$TORCH" --index-url "$TORCH_INDEX"
    exit 0
fi
if command -v "$NVIDIA_SMI" >/dev/null 2>&1; then
    echo "torch: the CUDA build of $TORCH from the configured index (an NVIDIA GPU: $NVIDIA_SMI found)"
    pip install -q "$TORCH"
    exit 0
fi
# What the configured index would install (a dry run reads metadata only).
offered=$(pip install --dry-run --no-deps --quiet --ignore-installed --report - "$TORCH" 2>/dev/null |
          "$PYTHON" -c 'import json, sys; print(json.load(sys.stdin)["install"][0]["metadata"]["version"])' \
          2>/dev/null || true)
case "$offered" in
    *+cpu)
        echo "torch: the CPU build of $TORCH (no NVIDIA GPU; the configured index serves $offered)"
        pip install -q "$TORCH"
        ;;
    *)
        echo "torch: the CPU build of $TORCH from $CPU_INDEX (no NVIDIA GPU; the configured index offers ${offered:-no build})"
        if ! pip install -q "$TORCH" --index-url "$CPU_INDEX"; then
            echo "torch: $CPU_INDEX cannot be reached; $TORCH from the configured index instead"
            pip install -q "$TORCH"
        fi
        ;;
esac
