#!/usr/bin/env python3
"""A class-adaptive linear stage on top of a model, fitted in closed form: does it add to it?

Every pixel is put in a class by the local structure of the model's output (the orientation of
its gradient in QA bins, its strength relative to the scene's mean in QS quantile bins, its
coherence in QC bins; structure tensor of the band mean over a 5 x 5 box) and its mosaic phase;
per class and phase a K x K window of the coded frame (both buckets' windows for a two-bucket
model) plus a bias maps linearly to the 31-band correction truth - model, fitted by ridge
regression on the training scenes (clean frames). Printed: mean PSNR of the model and of
model + correction on the training, validation and test scenes (split as the program splits
them: `lumosaic eval` names them; prepared as `eval` prepares them: cropped to whole tiles,
divided by their maximum).

    build/venv/bin/python scripts/class_floor.py models/zoo/lmmse
    build/venv/bin/python scripts/class_floor.py models/demo/tn160nc-lmmse.safetensors
    build/venv/bin/python scripts/class_floor.py models/zoo/lmmse-b2 --buckets 2

Needs the Python package (scripts/test_python.sh installs it into build/venv), numpy and the
built program (build/lumosaic, or --cli). Run from the top of the checkout.
"""
import argparse
import os
import re
import subprocess
import sys

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

import lumosaic

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def split_names(cli, folders, split):
    """The scenes of a split, as the program splits them (its `eval` names each scene scored)."""
    if not os.access(cli, os.X_OK):
        sys.exit(f"class_floor: {cli}: no lumosaic program (build it, or give --cli)")
    r = subprocess.run([cli, "eval", "--model", os.path.join(REPO, "models/zoo/lmmse"), *folders,
                        "--split", split, "--noise", "0", "--rainbow", "0", "--threads", "1"],
                       capture_output=True, text=True)
    if r.returncode != 0:
        last = (r.stderr.strip().splitlines() or ["eval failed"])[-1]
        sys.exit(f"class_floor: the {split} split: {last}")
    return set(re.findall(r"^scene \d+/\d+ (\S+) \(", r.stderr, re.M))


def scenes(folders):
    out = []
    for d in folders:
        if not os.path.isdir(d):
            sys.exit(f"class_floor: {d}: not a folder of scenes")
        for name in sorted(os.listdir(d)):
            path = os.path.join(d, name)
            if os.path.isdir(path):
                out.append((name, path))
    return out


def windows(plane, k):
    """(H, W, k*k): the k x k window of every pixel, borders reflected."""
    r = k // 2
    padded = np.pad(plane, r, mode="reflect")
    h, w = plane.shape
    return sliding_window_view(padded, (k, k)).reshape(h, w, k * k)


def features(planes, k):
    h, w = planes[0].shape
    parts = [windows(p, k) for p in planes] + [np.ones((h, w, 1), np.float32)]
    return np.concatenate(parts, axis=2)


def structure(out):
    """Orientation (0..pi), relative strength and coherence of the band mean's gradient."""
    g = out.mean(axis=2)
    gy, gx = np.gradient(g)

    def box(a, n=5):
        return sliding_window_view(np.pad(a, n // 2, mode="reflect"), (n, n)).mean(axis=(2, 3))

    a, b, c = box(gx * gx), box(gx * gy), box(gy * gy)
    half_tr = (a + c) / 2
    d = np.sqrt(np.maximum(half_tr * half_tr - (a * c - b * b), 0))
    l1, l2 = np.sqrt(half_tr + d), np.sqrt(np.maximum(half_tr - d, 0))
    theta = 0.5 * np.arctan2(2 * b, a - c) + np.pi / 2
    return theta, l1 / (g.mean() + 1e-3), (l1 - l2) / (l1 + l2 + 1e-9)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("model")
    ap.add_argument("--buckets", type=int, default=1, choices=(1, 2))
    ap.add_argument("--k", type=int, default=7, help="window (odd)")
    ap.add_argument("--ridge", type=float, default=1e-3, help="ridge per sample")
    ap.add_argument("--qa", type=int, default=8)
    ap.add_argument("--qs", type=int, default=3)
    ap.add_argument("--qc", type=int, default=2)
    ap.add_argument("--data", nargs="+", default=["../shared/data/cave", "../shared/data/cave-256"])
    ap.add_argument("--cli", default=os.path.join(REPO, "build/lumosaic"),
                    help="the lumosaic program (names each split's scenes)")
    a = ap.parse_args()
    if a.k < 1 or a.k % 2 == 0:
        sys.exit(f"class_floor: --k {a.k}: an odd window of at least 1")
    try:
        model = lumosaic.Model(a.model)
    except lumosaic.Error as e:
        sys.exit(f"class_floor: {e}")
    if model.buckets != a.buckets:
        sys.exit(f"class_floor: {a.model} reads {model.buckets} bucket(s): give --buckets "
                 f"{model.buckets}")
    tr, tc = model.tile
    found = scenes(a.data)
    test, val = split_names(a.cli, a.data, "test"), split_names(a.cli, a.data, "val")
    rows = []
    for name, path in found:
        cube = lumosaic.read_cube(path).astype(np.float32)
        h, w = cube.shape[0] // tr * tr, cube.shape[1] // tc * tc
        cube = np.ascontiguousarray(cube[:h, :w])
        cube /= cube.max()
        if a.buckets == 2:
            f1, b0 = lumosaic.simulate(cube, noise=0.0, bucket0=True, threads=1)
            planes = [np.ascontiguousarray(f1, np.float32), np.ascontiguousarray(b0, np.float32)]
            out = model.reconstruct(planes[0], bucket0=planes[1], noise=0.0)
        else:
            planes = [np.ascontiguousarray(lumosaic.simulate(cube, noise=0.0, threads=1),
                                           np.float32)]
            out = model.reconstruct(planes[0], noise=0.0)
        split = "test" if name in test else "val" if name in val else "train"
        rows.append((name, split, cube, planes, out))
    train = [r for r in rows if r[1] == "train"]
    if not train:
        sys.exit("class_floor: no training scenes")
    st = [structure(r[4]) for r in train]
    s_edges = np.quantile(np.concatenate([s[1].ravel() for s in st]),
                          np.linspace(0, 1, a.qs + 1)[1:-1])
    c_edges = np.quantile(np.concatenate([s[2].ravel() for s in st]),
                          np.linspace(0, 1, a.qc + 1)[1:-1])
    ncls = a.qa * a.qs * a.qc

    def groups(out):
        theta, s, c = structure(out)
        ang = (theta / np.pi * a.qa).astype(int) % a.qa
        cls = (ang * a.qs + np.searchsorted(s_edges, s)) * a.qc + np.searchsorted(c_edges, c)
        h, w = cls.shape
        phase = (np.arange(h)[:, None] % tr) * tc + np.arange(w)[None, :] % tc
        return (phase * ncls + cls).ravel()

    ngroups = tr * tc * ncls
    nf = a.k * a.k * a.buckets + 1
    ata = np.zeros((ngroups, nf, nf))
    atb = np.zeros((ngroups, nf, 31))
    count = np.zeros(ngroups)
    for name, split, cube, planes, out in train:
        x = features(planes, a.k).reshape(-1, nf).astype(np.float64)
        y = (cube - out).reshape(-1, 31).astype(np.float64)
        g = groups(out)
        order = np.argsort(g, kind="stable")
        bounds = np.searchsorted(g[order], np.arange(ngroups + 1))
        for k in range(ngroups):
            sel = order[bounds[k]:bounds[k + 1]]
            if sel.size:
                ata[k] += x[sel].T @ x[sel]
                atb[k] += x[sel].T @ y[sel]
                count[k] += sel.size
    eye = np.eye(nf)
    wts = np.stack([np.linalg.solve(ata[k] + (a.ridge * max(count[k], 1) + 1e-9) * eye, atb[k])
                    for k in range(ngroups)])

    def psnr(x, y):
        return 10 * np.log10(1.0 / np.mean((x - y) ** 2))

    print(f"{a.model}: {ncls} classes x {tr * tc} phases, window {a.k}, ridge {a.ridge}, "
          f"smallest group {int(count.min())} pixels")
    for split in ("train", "val", "test"):
        base, adapted = [], []
        for name, sp, cube, planes, out in rows:
            if sp != split:
                continue
            h, w = cube.shape[:2]
            x = features(planes, a.k).reshape(-1, nf)
            corr = np.einsum("nf,nfc->nc", x, wts[groups(out)]).reshape(h, w, 31)
            base.append(psnr(out, cube))
            adapted.append(psnr(np.maximum(out + corr, 0), cube))
        if base:
            print(f"  {split:5s} ({len(base):2d} scenes)  model {np.mean(base):6.2f} dB   "
                  f"+ class-adaptive stage {np.mean(adapted):6.2f} dB")


if __name__ == "__main__":
    main()
