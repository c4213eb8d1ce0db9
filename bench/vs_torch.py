#!/usr/bin/env python3
"""vs_torch.py — Lumosaic vs a PyTorch twin, side by side on this machine (one command).

  python3 bench/vs_torch.py --build build --threads 2 [--presets linear,han-tiny,...]

For each preset: (1) agreement — `bench_twin --mode dump` writes the seeded weights, a raw batch,
the forward output, the L1 loss, every parameter gradient and one small folded frame; the twin
(bench/torch_twin.py) loads the weights by name, recomputes all of it, and this driver FAILS
(exit status 1, "AGREEMENT FAILED") when a norm-wise relative difference ||twin - ours|| / ||ours||
exceeds the tolerances below; (2) training step (forward, L1, backward, Adam) at batch 4 of
66 x 64, or no-grad forward for han-paper; (3) one 640 x 480 frame through the §8 window fold
(batch 8 windows). Each run is its own child process (peak memory = the child's ru_maxrss);
the two sides are interleaved C, torch, C, torch (--rounds) and min / median over all timed
repetitions are reported. Ratio = torch / Lumosaic (> 1: Lumosaic is faster).
--scaling P1,P2 adds frame time vs frame size (160x120 .. 1280x960) at 1 and 2 threads.

Only the twin needs torch: the driver looks for a Python that imports it in $LM_TORCH_PYTHON,
`python3` on PATH, then /usr/bin/python3, and says so if none does. Standard library only here.
"""
import argparse
import json
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
TWIN = os.path.join(HERE, "torch_twin.py")
DEFAULT_PRESETS = "linear,han-tiny,han-small,mcan,srnet,han-paper"
FORWARD_ONLY = {"han-paper"}       # too big to train on a CPU: forward at batch 4 only
NO_FRAME = {"han-paper"}           # ~70 TMAC per frame: hours on 2 cores
# Agreement tolerances (norm-wise relative difference, float32 on both sides). Measured values
# are ~1e-7..1e-6 for outputs and ~1e-6..3e-4 for gradients (bias gradients of the last layer
# and LAM's gamma are sums with heavy cancellation, hence the looser gradient bound).
TOL = {"out": 1e-4, "loss": 1e-5, "grad_max": 2e-3, "frame": 1e-4}
SCALING_SIZES = [(120, 160), (240, 320), (480, 640), (960, 1280)]


def find_torch_python():
    cands = [os.environ.get("LM_TORCH_PYTHON"), shutil.which("python3"), "/usr/bin/python3"]
    tried = []
    for p in cands:
        if not p or p in tried:
            continue
        tried.append(p)
        try:
            r = subprocess.run([p, "-c", "import torch; print(torch.__version__)"],
                               capture_output=True, text=True, timeout=120)
        except (OSError, subprocess.TimeoutExpired):
            continue
        if r.returncode == 0:
            return p, r.stdout.strip()
    return None, tried


def c_env():
    """The C side's environment: OpenMP threads wait as `lumosaic train` makes them wait
    (cli/main.c: GOMP_SPINCOUNT=1000, spin briefly then sleep) unless the caller chose a policy
    (OMP_WAIT_POLICY or GOMP_SPINCOUNT set): bench_twin is not the CLI and would otherwise run
    with libgomp's default of ~300,000 spins, which the product does not use."""
    env = dict(os.environ)
    if "OMP_WAIT_POLICY" not in env and "GOMP_SPINCOUNT" not in env:
        env["GOMP_SPINCOUNT"] = "1000"
    return env


def run_child(cmd, env=None):
    """Run a child, reaping it with wait4 so ru_maxrss is this child's alone; returns (the last
    JSON line of its stdout, its peak resident memory in MB)."""
    with tempfile.TemporaryFile("w+") as fo, tempfile.TemporaryFile("w+") as fe:
        proc = subprocess.Popen(cmd, stdout=fo, stderr=fe, text=True, env=env)
        _, status, ru = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        fo.seek(0), fe.seek(0)
        out, err = fo.read(), fe.read()
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{err.strip()[-2000:]}")
    lines = [l for l in out.splitlines() if l.startswith("{")]
    return json.loads(lines[-1]), ru.ru_maxrss / 1024.0


def agreement(a, py, preset, dump):
    fwd_only = preset in FORWARD_ONLY
    cmd = [a.twin_c, "--preset", preset, "--mode", "dump", "--out", dump, "--threads",
           str(a.threads)]
    if preset.startswith("han"):
        cmd += ["--gamma", "0.5"]          # exercise LAM and CSAM (their gammas init to 0)
    if fwd_only:
        cmd += ["--batch", "1", "--no-grad-dump"]
    else:
        cmd += ["--frame-h", "120", "--frame-w", "160"]
    run_child(cmd)
    res, _ = run_child([py, TWIN, "--preset", preset, "--mode", "check", "--dump", dump,
                        "--threads", str(a.threads)])
    bad = [f"{k} {res[k]:.2e} > {t:.0e}" for k, t in TOL.items() if k in res and not res[k] <= t]
    return res, bad


def timed_pair(a, py, preset, mode, dump, reps, warmup, extra=(), threads=None):
    """Interleave C and torch runs (a.rounds each); pool the repetition times."""
    th = str(threads or a.threads)
    c_cmd = [a.twin_c, "--preset", preset, "--mode", mode, "--threads", th, "--reps", str(reps),
             "--warmup", str(warmup), *extra]
    t_cmd = [py, TWIN, "--preset", preset, "--mode", mode, "--dump", dump, "--threads", th,
             "--reps", str(reps), "--warmup", str(warmup), *extra]
    side = {"c": {"t": [], "mb": 0.0}, "torch": {"t": [], "mb": 0.0}}
    for _ in range(a.rounds):
        for name, cmd in (("c", c_cmd), ("torch", t_cmd)):
            r, mb = run_child(cmd, c_env() if name == "c" else None)
            side[name]["t"] += r["times_ms"]
            side[name]["mb"] = max(side[name]["mb"], mb)
    for s in side.values():
        s["min"], s["median"] = min(s["t"]), statistics.median(s["t"])
    return side


def fmt_row(preset, what, s):
    c, t = s["c"], s["torch"]
    return (f"{preset:<10} {what:<8} {c['min']:>9.1f} {c['median']:>9.1f} {t['min']:>9.1f} "
            f"{t['median']:>9.1f} {t['min'] / c['min']:>6.2f} {t['median'] / c['median']:>6.2f} "
            f"{c['mb']:>8.0f} {t['mb']:>8.0f}")


def main():
    ap = argparse.ArgumentParser(description="Lumosaic vs PyTorch twin (see file header)")
    ap.add_argument("--build", default="build", help="CMake build dir holding bench_twin")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--presets", default=DEFAULT_PRESETS)
    ap.add_argument("--reps", type=int, default=5, help="timed training steps per run")
    ap.add_argument("--rounds", type=int, default=2, help="interleaved runs per side")
    ap.add_argument("--frame-reps", type=int, default=1)
    ap.add_argument("--no-frame", action="store_true")
    ap.add_argument("--scaling", default="", help="presets for frame size / thread scaling")
    ap.add_argument("--json", help="also write all results here")
    a = ap.parse_args()
    a.twin_c = os.path.join(a.build, "bench_twin")
    if not os.access(a.twin_c, os.X_OK):
        sys.exit(f"vs_torch: {a.twin_c} not found: cmake --build {a.build} --target bench_twin")
    py, ver = find_torch_python()
    if not py:
        sys.exit("vs_torch: no Python with torch found (tried $LM_TORCH_PYTHON, python3, "
                 f"/usr/bin/python3: {ver}); install PyTorch or set LM_TORCH_PYTHON")
    print(f"# Lumosaic {a.twin_c} vs PyTorch {ver} ({py}), {a.threads} threads, "
          f"{a.rounds} interleaved runs per side; times in ms, peak RSS in MB")
    print(f"# agreement tolerances (norm-wise relative): {TOL}")
    print("# C side's OpenMP wait policy: GOMP_SPINCOUNT=%s (as lumosaic train; OMP_WAIT_POLICY %s)"
          % (c_env().get("GOMP_SPINCOUNT", "default"), os.environ.get("OMP_WAIT_POLICY", "unset")))
    print("# load average at start: %.1f %.1f %.1f (a shared machine: compare min columns)"
          % os.getloadavg(), flush=True)
    results, failed = {}, []
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))   # still removes the dumps
    tmp = tempfile.mkdtemp(prefix="vs_torch_")
    try:
        rows = []
        for preset in [p for p in a.presets.split(",") if p]:
            dump = os.path.join(tmp, preset + ".safetensors")
            res, bad = agreement(a, py, preset, dump)
            res.pop("grads", None)
            agree = " ".join(f"{k}={res[k]:.1e}" for k in TOL if k in res)
            print(f"{preset:<10} agreement {'OK' if not bad else 'FAILED'}: {agree}"
                  + (f" (worst grad {res['grad_worst']})" if "grad_worst" in res else ""), flush=True)
            results[preset] = {"agreement": res}
            if bad:
                failed.append(f"{preset}: {', '.join(bad)}")
                continue
            fwd = preset in FORWARD_ONLY
            mode, reps, warm = ("forward", 1, 0) if fwd else ("step", a.reps, 1)
            s = timed_pair(a, py, preset, mode, dump, reps, warm)
            results[preset][mode] = s
            rows.append(fmt_row(preset, mode, s))
            print(rows[-1], flush=True)
            if not a.no_frame and preset not in NO_FRAME:
                s = timed_pair(a, py, preset, "frame", dump, a.frame_reps, 0)
                results[preset]["frame"] = s
                rows.append(fmt_row(preset, "frame", s))
                print(rows[-1], flush=True)
        hdr = (f"{'preset':<10} {'what':<8} {'C min':>9} {'C med':>9} {'pt min':>9} {'pt med':>9} "
               f"{'r min':>6} {'r med':>6} {'C MB':>8} {'pt MB':>8}")
        print("\n" + hdr + "\n" + "\n".join(rows))
        print("# load average at end: %.1f %.1f %.1f" % os.getloadavg())
        print("# step = forward + L1 + backward + Adam, batch 4 x 66x64; forward = no-grad batch 4; "
              "frame = 640x480, windows 66x64 stride 30x32, batch 8; r = torch / Lumosaic")
        for preset in [p for p in a.scaling.split(",") if p]:
            dump = os.path.join(tmp, preset + ".safetensors")
            if not os.path.exists(dump):
                agreement(a, py, preset, dump)
            print(f"\n# scaling {preset}: frame time (ms, min) vs size and threads")
            print(f"{'HxW':>10} {'C 1t':>9} {'pt 1t':>9} {'C 2t':>9} {'pt 2t':>9} {'C x2t':>8}")
            for h, w in SCALING_SIZES:
                ext = ["--height", str(h), "--width", str(w)]
                s1 = timed_pair(a, py, preset, "frame", dump, a.frame_reps, 0, ext, threads=1)
                s2 = timed_pair(a, py, preset, "frame", dump, a.frame_reps, 0, ext, threads=2)
                results.setdefault(preset, {})[f"scaling_{h}x{w}"] = {"1": s1, "2": s2}
                print(f"{f'{h}x{w}':>10} {s1['c']['min']:>9.1f} {s1['torch']['min']:>9.1f} "
                      f"{s2['c']['min']:>9.1f} {s2['torch']['min']:>9.1f} "
                      f"{s1['c']['min'] / s2['c']['min']:>8.2f}", flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(results, f, indent=1)
    if failed:
        print("\nAGREEMENT FAILED:\n  " + "\n  ".join(failed), file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
