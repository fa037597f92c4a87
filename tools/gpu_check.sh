#!/usr/bin/env bash
# The GPU figures of docs/RESULTS.md section 8 in one run of at most 8 minutes, on an NVIDIA machine:
#   offscreen_1080p  the previewer through EGL at 1920x1080: per-pixel decoder (no baked body table), compute path
#   window_1080p     `nbrdf bench app --size 1920x1080` (only where $DISPLAY is set: the window needs one)
#   bench_render     `nbrdf bench render --size 1920x1080` (per-1080p frame, share of the GPU's FP32 peak)
#   mitsuba_cuda     the `nbrdf` plugin in Mitsuba's cuda_ad_rgb: the scenes rendered (table and decoder bodies),
#                    then the equal-time report (the paper's Table 3) with the time left
#   walk_cuda        `NBRDF_WALK_DEVICE=cuda nbrdf bench reference`, then the CUDA walk against the CPU walk
# Every step has its own `timeout` and fails soft: the JSON says ok / failed / skipped with a one-line reason.
#
# Usage: bash tools/gpu_check.sh [--dry-run] [--only STEP,...] [OUT.json]
#   OUT.json    default: $OUT/gpu_check.json, else ./gpu_check.json
#   --dry-run   tiny sizes and counts: checks the script and the JSON on any machine (about 2 min on 2 loaded
#               cores); without CUDA the CUDA steps fail soft with their reason
#   --only      run these steps (setup always runs); the others are recorded as skipped
#
# Requirements (said once here, checked by the `setup` step, which records what is missing):
#   - python3 with torch and numpy; the steps import moderngl + glcontext (EGL), imageio, OpenEXR, safetensors
#     (previewer), mitsuba + drjit (mitsuba_cuda), numba + numba-cuda (walk_cuda).
#   - The interpreter: $NBRDF_PYTHON, else the repository's .venv if it imports nbrdf, else python3 with the
#     repository put on its path (no install needed). Missing packages come from wheels in $NBRDF_WHEELS (default
#     .whl/, made beforehand where pip reaches a registry: `pip download --no-deps --only-binary=:all:
#     --python-version 3.12 --platform manylinux2014_x86_64 -d .whl NAME` for each), else from the package
#     registry if it answers within 10 s; nothing else is fetched. A dry run installs nothing.
#   - OpenGL through EGL with the NVIDIA driver: where libEGL is absent and .gl/*.deb exist (libegl1 libglvnd0
#     libopengl0 libgl1 libglx0 libgles2), they are unpacked into / (root); __EGL_VENDOR_LIBRARY_FILENAMES points
#     at the NVIDIA vendor file when it exists. The JSON records the GL renderer: llvmpipe there means a CPU figure.
# Overrides for checking the steps without a GPU: GPU_CHECK_MI_VARIANT (default cuda_ad_rgb),
# GPU_CHECK_WALK_DEVICE (default cuda), GPU_CHECK_BUDGET_S (default 480).
set -u

DRY=0
JSON=""
ONLY=""
while [ $# -gt 0 ]; do
    case "$1" in
        --dry-run) DRY=1 ;;
        --only) ONLY=${2:?--only needs a list of steps}; shift ;;
        --only=*) ONLY=${1#--only=} ;;
        -h|--help) sed -n '2,/^set -u/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
        -*) echo "gpu_check: unknown option $1" >&2; exit 2 ;;
        *) JSON=$1 ;;
    esac
    shift
done
JSON=${JSON:-${OUT:-.}/gpu_check.json}
REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$REPO" || exit 2
BUDGET=${GPU_CHECK_BUDGET_S:-480}
RESERVE=15                      # seconds kept for writing the JSON
MI_VARIANT=${GPU_CHECK_MI_VARIANT:-cuda_ad_rgb}
WALK_DEVICE=${GPU_CHECK_WALK_DEVICE:-cuda}
WORK=$(mktemp -d "${TMPDIR:-/tmp}/gpu_check.XXXXXX")
START=$(date +%s)
export PYTHONUNBUFFERED=1 NBRDF_STATE_DIR="$WORK/state" NBRDF_IDLE_REFINE=0
if [ "$DRY" = 1 ]; then
    SIZE=64x36; SPP=4; REPEATS=1; STORAGES=ubo; MI_SIZE=32x24; MI_SPP=8; SCENES=still_life; REF_SPP=32
    MI_BUDGET=0.5; QUICK=--quick
else
    SIZE=1920x1080; SPP=64; REPEATS=3; STORAGES=texture,ssbo,ubo,const; MI_SIZE=320x240; MI_SPP=64
    SCENES=still_life,teapot,globe,torus; REF_SPP=1024; MI_BUDGET=2; QUICK=
fi

elapsed() { echo $(( $(date +%s) - START )); }
log() { echo "gpu_check [$(elapsed) s] $*" >&2; }

# run_step NAME MAX_SECONDS CMD...: CMD under `timeout` (at most MAX_SECONDS and what the budget leaves);
# its stdout, stderr, exit status and seconds go to $WORK/NAME.* for the JSON.
run_step() {
    local name=$1 max=$2
    shift 2
    if [ -n "$ONLY" ] && [[ ",$ONLY," != *",$name,"* ]]; then
        skip_step "$name" "not in --only $ONLY"
        return
    fi
    local left=$(( BUDGET - $(elapsed) - RESERVE ))
    local limit=$(( max < left ? max : left ))
    echo "$name" >> "$WORK/order"
    printf '%s ' "$@" | cut -c1-300 > "$WORK/$name.cmd"
    if (( limit < 5 )); then
        echo "the ${BUDGET} s budget is spent" > "$WORK/$name.skip"
        log "$name: skipped (budget spent)"
        return
    fi
    echo "$limit" > "$WORK/$name.limit"
    local t0 t1
    t0=$(date +%s.%N)
    timeout --kill-after=10 "$limit" "$@" > "$WORK/$name.out" 2> "$WORK/$name.err"
    echo $? > "$WORK/$name.rc"
    t1=$(date +%s.%N)
    echo "$t0 $t1" | awk '{printf "%.2f\n", $2 - $1}' > "$WORK/$name.sec"
    log "$name: exit $(cat "$WORK/$name.rc") in $(cat "$WORK/$name.sec") s"
}

skip_step() {  # NAME REASON
    echo "$1" >> "$WORK/order"
    echo "$2" > "$WORK/$1.skip"
    log "$1: skipped ($2)"
}

# --- the device -----------------------------------------------------------------------------------------------
if command -v nvidia-smi > /dev/null; then
    timeout 20 nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader,nounits \
        > "$WORK/nvidia_smi.out" 2> "$WORK/nvidia_smi.err"
    echo $? > "$WORK/nvidia_smi.rc"
else
    echo "nvidia-smi not found: no NVIDIA driver on this machine" > "$WORK/nvidia_smi.err"
    echo 127 > "$WORK/nvidia_smi.rc"
fi

# --- setup: interpreter, nbrdf on its path, missing packages, EGL -------------------------------------------------
SETUP_T0=$(date +%s.%N)
{
    PY=${NBRDF_PYTHON:-}
    if [ -z "$PY" ]; then
        if [ -x .venv/bin/python ] && .venv/bin/python -c "import nbrdf.cli" 2> /dev/null; then
            PY=$REPO/.venv/bin/python
        else
            PY=$(command -v python3 || echo python3)
        fi
    fi
    echo "python: $PY"
    if ! "$PY" -c "import nbrdf.cli, nbrdf.viewer" 2> /dev/null; then
        # the repository's folders as the namespace package nbrdf (pyproject's package-dir), without installing
        mkdir -p "$WORK/shim/nbrdf"
        for d in cli neural training viewer imaging; do ln -s "$REPO/$d" "$WORK/shim/nbrdf/$d"; done
        ln -s "$REPO/mitsuba_plugin" "$WORK/shim/nbrdf/mitsuba"
        export PYTHONPATH="$WORK/shim${PYTHONPATH:+:$PYTHONPATH}"
        echo "nbrdf: the repository on PYTHONPATH ($WORK/shim)"
    fi
    MISSING=$("$PY" - <<'EOF'
import importlib.util
pip_names = {"torch": "torch", "numpy": "numpy", "moderngl": "moderngl", "glcontext": "glcontext",
             "imageio": "imageio", "OpenEXR": "OpenEXR", "safetensors": "safetensors", "tqdm": "tqdm",
             "mitsuba": "mitsuba", "drjit": "drjit", "numba": "numba", "numba_cuda": "numba-cuda"}
print(" ".join(p for m, p in pip_names.items() if importlib.util.find_spec(m) is None))
EOF
)
    WHEELS=${NBRDF_WHEELS:-$REPO/.whl}
    if [ -n "$MISSING" ] && [ "$DRY" = 1 ]; then
        echo "missing: $MISSING (a dry run installs nothing)"
    elif [ -n "$MISSING" ]; then
        echo "missing: $MISSING"
        mkdir -p "$WORK/site"
        if compgen -G "$WHEELS/*.whl" > /dev/null; then
            echo "installing the wheels of $WHEELS"
            timeout 150 "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir \
                --target "$WORK/site" "$WHEELS"/*.whl || echo "pip: the wheels of $WHEELS did not install"
        else
            echo "no wheels in $WHEELS: asking the package registry (10 s timeout)"
            # shellcheck disable=SC2086  # one name per word
            timeout 150 "$PY" -m pip install -q --no-deps --no-compile --timeout 10 --retries 0 \
                --target "$WORK/site" $MISSING || echo "pip: the registry gave nothing for: $MISSING"
        fi
        export PYTHONPATH="$WORK/site${PYTHONPATH:+:$PYTHONPATH}"
    fi
    if [ "$DRY" = 0 ] && [ -d "$REPO/.gl" ] && ! ldconfig -p 2> /dev/null | grep -q "libEGL.so.1"; then
        echo "unpacking .gl/*.deb (libEGL and glvnd)"
        for f in "$REPO"/.gl/*.deb; do dpkg -x "$f" / || echo "dpkg -x $f failed"; done
        ldconfig
    fi
    VENDOR=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
    if [ -z "${__EGL_VENDOR_LIBRARY_FILENAMES:-}" ] && [ -f "$VENDOR" ]; then
        export __EGL_VENDOR_LIBRARY_FILENAMES=$VENDOR
        echo "EGL vendor: $VENDOR"
    fi
} > "$WORK/setup.err" 2>&1
echo "setup" >> "$WORK/order"
"$PY" - > "$WORK/setup.out" 2>> "$WORK/setup.err" <<'EOF'
import importlib, json, sys
mods = ("torch", "numpy", "moderngl", "glcontext", "imageio", "OpenEXR", "safetensors", "mitsuba", "drjit",
        "numba", "numba_cuda")
found = {}
for m in mods:
    try:
        found[m] = getattr(importlib.import_module(m), "__version__", "yes")
    except Exception as e:  # noqa: BLE001 - recorded, the steps that need it fail with it
        found[m] = None
        print(f"{m}: {type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}", file=sys.stderr)
cuda = None
try:
    import torch
    cuda = torch.cuda.get_device_name(0) if torch.cuda.is_available() else None
except Exception:  # noqa: BLE001
    pass
try:
    import nbrdf.cli  # noqa: F401
    nbrdf_ok = True
except Exception as e:  # noqa: BLE001
    nbrdf_ok = False
    print(f"nbrdf: {type(e).__name__}: {e}", file=sys.stderr)
print(json.dumps({"python": sys.executable, "python_version": sys.version.split()[0], "modules": found,
                  "torch_cuda_device": cuda, "nbrdf_importable": nbrdf_ok}))
sys.exit(0 if nbrdf_ok and all(found[m] for m in ("torch", "numpy", "moderngl")) else 1)
EOF
echo $? > "$WORK/setup.rc"
echo "$SETUP_T0 $(date +%s.%N)" | awk '{printf "%.2f\n", $2 - $1}' > "$WORK/setup.sec"
log "setup: exit $(cat "$WORK/setup.rc") ($PY)"
NBRDF=("$PY" -m nbrdf.cli.main)

# --- offscreen_1080p: the previewer's frame through EGL, decoder per pixel, compute path ---------------------------
read -r -d '' OFFSCREEN_PY <<'EOF'
import json, sys, time
w, h = (int(v) for v in sys.argv[1].split("x"))
spp = int(sys.argv[2])
t0 = time.perf_counter()
from nbrdf.viewer.gpu.gl import describe, offscreen_context, use_compute
from nbrdf.viewer.options import ViewOptions
from nbrdf.viewer.session.lookdev import LookDev

ctx = offscreen_context()
opts = ViewOptions(size=(w, h), spp=spp, offscreen=True, brdf="neural")
ld = LookDev.from_options(ctx, opts, brdf=opts.brdf, threaded=False)
ld.bodies.use_tables = False  # the per-pixel decoder in every pass, as on a GPU after calibration
t1 = time.perf_counter()
ld.render_linear((w, h), 1)  # compiles and warms the programs
t2 = time.perf_counter()
one = ld.render_linear((w, h), 1)
t3 = time.perf_counter()
img = ld.render_linear((w, h), spp)
t4 = time.perf_counter()
ok = bool((img == img).all()) and float(img.mean()) > 0
print(json.dumps({
    "renderer": describe(ctx), "on_gpu": "llvmpipe" not in describe(ctx).lower(),
    "compute_path": use_compute(ctx), "body": "table" if ld.bodies.use_tables else "decoder per pixel",
    "brdf_kind": str(ld.brdf.kind.value), "size": f"{w}x{h}", "passes": spp,
    "startup_s": round(t1 - t0, 3), "first_frame_s": round(t2 - t1, 3), "one_pass_ms": round(1000 * (t3 - t2), 2),
    "ms_per_pass": round(1000 * ((t4 - t3) - (t3 - t2)) / max(spp - 1, 1), 2), f"{spp}_passes_s": round(t4 - t3, 3),
    "image_mean": round(float(img.mean()), 5), "finite_and_lit": ok}))
ld.close()
sys.exit(0 if ok else 3)
EOF
run_step offscreen_1080p 90 "$PY" -c "$OFFSCREEN_PY" "$SIZE" "$SPP"

# --- window_1080p: the window's own bench (a display needed) -------------------------------------------------------
if [ -n "${DISPLAY:-}" ] || { [ -n "$ONLY" ] && [[ ",$ONLY," != *",window_1080p,"* ]]; }; then
    run_step window_1080p 90 "${NBRDF[@]}" bench app --size "$([ "$DRY" = 1 ] && echo 320x200 || echo 1920x1080)" \
        --edits "$([ "$DRY" = 1 ] && echo 2 || echo 8)"
else
    skip_step window_1080p "no DISPLAY: the window needs one (offscreen_1080p measures the same frame through EGL)"
fi

# --- bench_render -------------------------------------------------------------------------------------------------
run_step bench_render 150 "${NBRDF[@]}" bench render --size "$SIZE" --repeats "$REPEATS" --storages "$STORAGES"

# --- mitsuba_cuda -------------------------------------------------------------------------------------------------
read -r -d '' MITSUBA_PY <<'EOF'
import json, sys, time
variant, size, spp, scenes_arg, ref_spp, budget, limit, work = sys.argv[1:9]
w, h = (int(v) for v in size.split("x"))
deadline = time.monotonic() + float(limit) - 15
out = {"variant": variant, "renders": [], "reports": {}}
def emit():  # the figures so far, one line each time: a timeout keeps what was measured
    print("\n" + json.dumps(out, default=float), flush=True)
def line(e):
    return f"{type(e).__name__}: {str(e).strip().splitlines()[0] if str(e).strip() else ''}"[:300]
try:
    import mitsuba as mi
    mi.set_variant(variant)
    import nbrdf.mitsuba  # noqa: F401 - registers the plugins for the variant in force
    from nbrdf.mitsuba import render, scenes
    from nbrdf.mitsuba.scene_report import SceneReportConfig, run_scene_report
except Exception as e:  # noqa: BLE001
    out["error"] = f"{variant}: {line(e)}"
    emit()
    sys.exit(2)
failed = []
for name in scenes_arg.split(","):
    for body in ("table", "decoder"):
        if time.monotonic() > deadline:
            out["renders"].append({"scene": name, "body": body, "skipped": "time"})
            continue
        try:
            sc = scenes.with_body(scenes.load_scene(name), body)
            t0 = time.perf_counter()
            render.render(sc, (w, h), 4, seed=0, chunk_spp=4)  # kernels compiled
            t1 = time.perf_counter()
            r = render.render(sc, (w, h), int(spp), seed=1, chunk_spp=int(spp), exclude_compile=True)
            img_ok = bool((r.image == r.image).all()) and float(r.image.mean()) > 0
            out["renders"].append({"scene": name, "body": body, "wavefront": render.is_wavefront(sc),
                                   "first_render_s": round(t1 - t0, 3), "spp": r.spp, "seconds": round(r.seconds, 4),
                                   "spp_per_s": round(r.spp / max(r.seconds, 1e-9), 1),
                                   "compile_s_excluded": round(r.compile_seconds, 3), "finite_and_lit": img_ok})
            if not img_ok:
                failed.append(f"{name}/{body}: image not finite or black")
        except Exception as e:  # noqa: BLE001 - one scene's failure is recorded, the rest go on
            out["renders"].append({"scene": name, "body": body, "error": line(e)})
            failed.append(f"{name}/{body}: {line(e)}")
        emit()
for body in ("decoder", "table"):
    if time.monotonic() > deadline - 30:
        out["reports"][body] = {"skipped": "time"}
        continue
    try:
        cfg = SceneReportConfig(out=__import__("pathlib").Path(work) / f"scenes_{body}", scenes=tuple(scenes_arg.split(",")),
                                size=(96, 72) if w >= 96 else (w, h), time_budget=float(budget), ref_spp=int(ref_spp),
                                neural_body=body)
        res = run_scene_report(cfg, log=lambda *a: print(*a, file=sys.stderr))
        out["reports"][body] = {r["scene"]: {
            "mc_over_neural_ref_noise_removed": r["mse_ratio_mc_over_neural_ref_noise_removed"],
            "neural_spp": r["neural"]["spp"], "mc_spp": r["mc"]["spp"], "mse_neural": r["neural"]["mse"],
            "mse_mc": r["mc"]["mse"], "crossover_s": r["crossover_seconds"]} for r in res["scenes"]}
        out["reports"][body]["config"] = res["config"]
    except Exception as e:  # noqa: BLE001
        out["reports"][body] = {"error": line(e)}
        failed.append(f"report {body}: {line(e)}")
    emit()
if failed:
    print(f"{len(failed)} failed: {failed[0]}", file=sys.stderr)
sys.exit(3 if failed else 0)
EOF
MI_LIMIT=200
run_step mitsuba_cuda "$MI_LIMIT" "$PY" -c "$MITSUBA_PY" "$MI_VARIANT" "$MI_SIZE" "$MI_SPP" "$SCENES" "$REF_SPP" \
    "$MI_BUDGET" "$(( MI_LIMIT < BUDGET - $(elapsed) - RESERVE ? MI_LIMIT : BUDGET - $(elapsed) - RESERVE ))" "$WORK"

# --- walk_cuda ----------------------------------------------------------------------------------------------------
read -r -d '' WALK_PY <<'EOF'
import json, subprocess, sys, time
device, quick = sys.argv[1], sys.argv[2] == "--quick"
import os
env = dict(os.environ, NBRDF_WALK_DEVICE=device)
t0 = time.perf_counter()
r = subprocess.run([sys.executable, "-m", "nbrdf.cli.main", "bench", "reference"] + (["--quick"] if quick else []),
                   env=env, capture_output=True, text=True)
out = {"device": device, "bench_seconds": round(time.perf_counter() - t0, 2)}
if r.returncode != 0:
    err = [l for l in r.stderr.replace("\r", "\n").splitlines() if l.strip()]
    out["error"] = (err[-1] if err else f"exit {r.returncode}")[:300]
    print(json.dumps(out))
    print(out["error"], file=sys.stderr)
    sys.exit(2)
out["bench_reference"] = json.loads(r.stdout)
print(json.dumps(out), flush=True)  # kept if the CPU comparison below runs out of time
# the same pairs on the CPU and on the device: per-pair means agree to rounding
import torch
from nbrdf.neural.material import parse_material
from nbrdf.training.bench import STANDARD_STACK
from nbrdf.training.layered import simulate
from nbrdf.training.reference import stack_params
mat = parse_material(STANDARD_STACK)
n = 64 if quick else 1024
g = torch.Generator().manual_seed(3)
d = torch.nn.functional.normalize(torch.randn(2, n, 3, generator=g), dim=-1).abs()
means = {}
for dev in ("cpu", device):
    t = time.perf_counter()
    means[dev] = simulate(stack_params(mat, n), d[0], d[1], spp=64, seed=5, dtype=torch.float64, device=dev)[0]
    out[f"agreement_{dev}_s"] = round(time.perf_counter() - t, 3)
# the same random numbers per path: rounding (FMA, the device's libm) may flip a rare branch, never many
rel = ((means[device] - means["cpu"]).abs() / means["cpu"].abs().clamp_min(1e-12)).flatten()
out.update({"agreement_pairs": n, "agreement_max_rel_diff": rel.max().item(),
            "agreement_median_rel_diff": rel.median().item(), "agreement_over_1e-6": int((rel > 1e-6).sum())})
print(json.dumps(out))
if out["agreement_median_rel_diff"] > 1e-6:
    print(f"CUDA and CPU walks disagree: median relative difference {out['agreement_median_rel_diff']:.2e}",
          file=sys.stderr)
sys.exit(0 if out["agreement_median_rel_diff"] <= 1e-6 else 3)
EOF
run_step walk_cuda 150 "$PY" -c "$WALK_PY" "$WALK_DEVICE" "${QUICK:---full}"

# --- the JSON -----------------------------------------------------------------------------------------------------
mkdir -p "$(dirname "$JSON")"
python3 - "$WORK" "$JSON" "$DRY" "$BUDGET" "$START" "$(git -C "$REPO" rev-parse --short HEAD 2> /dev/null || echo none)" <<'EOF'
import json, os, socket, sys, time
from pathlib import Path
work, dest, dry, budget, start, commit = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3] == "1", int(sys.argv[4]), int(sys.argv[5]), sys.argv[6]

def read(name, default=""):
    p = work / name
    return p.read_text(errors="replace") if p.exists() else default

def last_line(text):
    lines = [l.strip() for l in text.replace("\r", "\n").splitlines() if l.strip()]
    return lines[-1][:300] if lines else ""

def parse_json(text):
    """The step's JSON: its whole stdout, else its last line that is one."""
    try:
        return json.loads(text)
    except ValueError:
        pass
    for line in reversed(text.splitlines()):  # a library's log lines (colour codes too) may come before it
        if "{" in line:
            try:
                return json.loads(line[line.index("{"):])
            except ValueError:
                continue
    return None

steps = {}
for name in dict.fromkeys(read("order").split()):
    if (work / f"{name}.skip").exists():
        steps[name] = {"status": "skipped", "reason": read(f"{name}.skip").strip(), "seconds": 0.0,
                       "command": read(f"{name}.cmd").strip() or None, "figures": None}
        continue
    rc = int(read(f"{name}.rc", "1").strip() or 1)
    limit = read(f"{name}.limit").strip()
    figures = parse_json(read(f"{name}.out"))
    reason = None
    if rc in (124, 137):
        reason = f"timed out after {limit} s"
    elif rc != 0:
        reason = (figures or {}).get("error") if isinstance(figures, dict) else None
        reason = reason or last_line(read(f"{name}.err")) or f"exit status {rc}"
    steps[name] = {"status": "ok" if rc == 0 else "failed", "reason": reason, "exit_status": rc,
                   "seconds": float(read(f"{name}.sec", "0") or 0), "limit_s": int(limit) if limit else None,
                   "command": read(f"{name}.cmd").strip() or None, "figures": figures}
smi_rc = int(read("nvidia_smi.rc", "1").strip() or 1)
fields = [f.strip() for f in read("nvidia_smi.out").splitlines()[0].split(",")] if smi_rc == 0 and read("nvidia_smi.out").strip() else []
device = ({"name": fields[0], "driver": fields[1] if len(fields) > 1 else None,
           "memory_mib": float(fields[2]) if len(fields) > 2 else None, "count": len(read("nvidia_smi.out").splitlines())}
          if fields else {"name": None, "reason": last_line(read("nvidia_smi.err")) or f"nvidia-smi exit {smi_rc}"})
result = {"tool": "tools/gpu_check.sh", "schema": 1, "dry_run": dry, "commit": commit, "host": socket.gethostname(),
          "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(start)), "budget_s": budget,
          "seconds": round(time.time() - start, 1), "device": device, "steps": steps,
          "summary": {s: sum(v["status"] == s for v in steps.values()) for s in ("ok", "failed", "skipped")}}
dest.write_text(json.dumps(result, indent=1, default=str))
print(f"gpu_check: {dest}: " + ", ".join(f"{k} {v['status']}" + (f" ({v['reason']})" if v["reason"] else "")
                                        for k, v in steps.items()), file=sys.stderr)
EOF
rc=$?
rm -rf "$WORK"
exit $rc
