#!/usr/bin/env bash
# The GPU checks of docs/performance.md in one run, on a machine with an NVIDIA GPU, a study
# binary built elsewhere (no Rust or CUDA toolkit needed at build time) and Python with pyarrow:
#   1. `study bench --backend cuda`: the GPU's figure on 65 536 gain sets of the peers' work unit;
#   2. `study run` of benches/gpu/million.toml (1 048 576 samples) end to end, Parquet written;
#   3. studies/gains_sweep.toml, studies/record_sweep.toml and benches/gpu/effects.toml on the GPU
#      and on the CPU: every metric within 1e-9 relative (agree.py).
# usage: benches/gpu/check.sh [STUDY_BINARY] [WORK_DIR]     (run from the repository root;
#        STUDY_BINARY defaults to target/release/study, WORK_DIR, where the tables go, to
#        /tmp/vshake-gpu). Without a usable GPU it stops after the first step, exit 1.
set -u
export PATH="$PATH:/usr/local/cuda/bin"
bin=${1:-target/release/study}
work=${2:-/tmp/vshake-gpu}
mkdir -p "$work"
# NVRTC: a CUDA toolkit's, or the nvidia-cuda-nvrtc wheel's (nvidia/cu13/lib); the driver's folder.
for d in /usr/local/cuda/lib64 /usr/local/nvidia/lib64 \
    $(python3 -c 'import nvidia, os; print(*[os.path.join(p, "cu13", "lib") for p in nvidia.__path__])' 2>/dev/null); do
    [ -d "$d" ] && LD_LIBRARY_PATH="$d${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
done
export LD_LIBRARY_PATH
fails=0
step() { # step NAME COMMAND...: runs it, prints its wall time and exit code
    local name=$1; shift
    echo "== $name: $*"
    local t0=$EPOCHREALTIME
    "$@"
    local rc=$?
    echo "== $name: rc $rc, $(awk "BEGIN { printf \"%.2f\", $EPOCHREALTIME - $t0 }") s wall"
    [ $rc -eq 0 ] || fails=$((fails + 1))
}
if command -v nvidia-smi >/dev/null; then
    echo "GPU: $(nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv,noheader)"
fi
echo "CPU cores: $(nproc)"
step bench "$bin" bench --backend cuda --seconds 1
if [ $fails -ne 0 ]; then # no GPU this binary can use: the cause is the line above
    echo "== stopped: study bench --backend cuda failed (its error above says why); nothing else was run"
    exit 1
fi
step million "$bin" run benches/gpu/million.toml --backend cuda --out "$work/million.parquet"
step million_rows python3 -c "
import pyarrow.parquet as pq, pyarrow.compute as pc, sys
t = pq.read_table(sys.argv[1]); ok = pc.sum(pc.equal(t['status'], 'ok')).as_py()
print(t.num_rows, 'rows,', ok, 'ok'); sys.exit(t.num_rows != 1048576)" "$work/million.parquet"
for s in studies/gains_sweep.toml studies/record_sweep.toml benches/gpu/effects.toml; do
    n=$(basename "$s" .toml)
    step "$n-cuda" "$bin" run "$s" --backend cuda --out "$work/$n-cuda.parquet"
    step "$n-cpu" "$bin" run "$s" --backend cpu --out "$work/$n-cpu.parquet"
    step "$n-agree" python3 benches/gpu/agree.py "$work/$n-cuda.parquet" "$work/$n-cpu.parquet" 1e-9
done
# Registers and spills of the cached kernels (ptxas of a CUDA toolkit, where there is one).
if command -v ptxas >/dev/null; then
    for p in "${XDG_CACHE_HOME:-$HOME/.cache}"/vshake/*.ptx; do
        ptxas -arch=sm_90 -v "$p" -o /dev/null 2>&1 | grep -E "registers|spill" | head -3
    done
fi
echo "== $fails step(s) failed"
exit $fails
