#!/usr/bin/env python3
"""mpi_scaling.py — data-parallel training throughput (issue 17): `lumosaic train` at 1 rank and
at N ranks (mpirun --oversubscribe, 1 thread each, batch B per rank), runs interleaved
(1, N, 1, N, ...) since this machine loses CPU to its host at times; prints samples/s min and
median, the seconds per update, and the share of each update spent in the gradient allreduce
(rank 0's MPI_Allreduce time, printed by train). Then a model of larger runs: for each preset,
the gradient (parameters x 4 bytes) summed by a ring allreduce over 8, 64 and 512 ranks,
2 (N - 1) / N x bytes / bandwidth + 2 (N - 1) x latency, against the measured compute time of an
update, on two interconnects (stated below); no overlap of communication with backward assumed
(train.c sums after the last micro-batch), so efficiency = compute / (compute + allreduce).

Not a test. Run it on a quiet machine:
    python3 bench/mpi_scaling.py --build build --presets rt-8,han-tiny --ranks 2 --iters 60
"""
import argparse, json, os, re, statistics, struct, subprocess, sys, tempfile, time

NETS = {"10 GbE (1.1 GB/s, 30 us)": (1.1e9, 30e-6), "InfiniBand HDR (11 GB/s, 2 us)": (11e9, 2e-6)}


def params_of(path):
    with open(path, "rb") as f:
        n = struct.unpack("<Q", f.read(8))[0]
        h = json.loads(f.read(n))
    return sum((v["data_offsets"][1] - v["data_offsets"][0]) // 4 for k, v in h.items()
               if k != "__metadata__")


def run(lm, preset, data, ranks, batch, iters, out, env):
    cmd = [lm, "train", "--model", preset, "--data", data, "--batch", str(batch),
           "--accum-steps", "1", "--iterations", str(iters), "--val-interval", "0",
           "--checkpoint-interval", "0", "--threads", "1", "--workers", "0", "--quiet",
           "--output", out]
    if ranks > 1:
        cmd = ["mpirun", "--oversubscribe", "-np", str(ranks)] + cmd
    t0 = time.monotonic()
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.monotonic() - t0
    if p.returncode:
        sys.exit(f"{' '.join(cmd)}: {p.stderr.strip()[-400:]}")
    m = re.search(r"\(([\d.]+) s this run\)", p.stdout)
    comm = re.search(r"gradient sums took ([\d.]+) s", p.stdout)
    return float(m.group(1)), float(comm.group(1)) if comm else 0.0, wall


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", default="build")
    ap.add_argument("--presets", default="rt-8,han-tiny")
    ap.add_argument("--data", default=os.path.join(os.path.dirname(__file__),
                                                   "../../shared/data/cave"))
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--batch", type=int, default=4)
    ap.add_argument("--iters", type=int, default=60)
    ap.add_argument("--reps", type=int, default=3)
    a = ap.parse_args()
    lm = os.path.join(a.build, "lumosaic")
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMP_WAIT_POLICY="passive")
    print(f"{a.iters} updates, batch {a.batch} per rank, 1 thread per rank, {a.reps} runs each "
          f"(interleaved); samples/s = ranks x batch x updates / training seconds")
    for preset in a.presets.split(","):
        res = {1: [], a.ranks: []}
        with tempfile.TemporaryDirectory() as tmp:
            for k in range(a.reps):
                for n in (1, a.ranks):
                    out = os.path.join(tmp, f"{n}_{k}")
                    secs, comm, wall = run(lm, preset, a.data, n, a.batch, a.iters, out, env)
                    res[n].append((n * a.batch * a.iters / secs, secs / a.iters, comm / a.iters))
            P = params_of(os.path.join(tmp, f"1_0", "model.safetensors"))
        print(f"\n{preset}: {P:,} parameters, gradient {4 * P / 1e6:.2f} MB")
        print(f"  {'ranks':>5} {'samples/s min':>14} {'median':>8} {'s/update med':>13} "
              f"{'allreduce s/update':>19} {'share':>6}")
        for n, r in res.items():
            sps = [x[0] for x in r]
            step = statistics.median(x[1] for x in r)
            comm = statistics.median(x[2] for x in r)
            print(f"  {n:>5} {min(sps):>14.1f} {statistics.median(sps):>8.1f} {step:>13.4f} "
                  f"{comm:>19.4f} {100 * comm / step:>5.1f}%")
        compute = statistics.median(x[1] for x in res[1])  # one rank's update, batch B
        for net, (bw, lat) in NETS.items():
            row = []
            for n in (8, 64, 512):
                t = 2 * (n - 1) / n * 4 * P / bw + 2 * (n - 1) * lat
                row.append(f"N={n}: {n * a.batch / (compute + t):,.0f} samples/s "
                           f"({100 * compute / (compute + t):.0f} %)")
            print(f"  model, {net}: " + "; ".join(row))


if __name__ == "__main__":
    main()
