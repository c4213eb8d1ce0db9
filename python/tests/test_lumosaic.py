"""The Python package against the `lumosaic` program and the C library's contract: cubes and
reconstructions equal to the commands' on the same inputs (same thread count), errors as
lumosaic.Error, hostile files as errors (not a dead interpreter), the GIL released during a
reconstruction, memory returned over 200 reconstructions, and the example script.

Environment: LUMOSAIC_CLI, the `lumosaic` program to compare with (default: build/lumosaic of
this checkout); LM_SHARED_DIR, the shared data (default: ../shared beside the checkout).
"""
import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import lumosaic

REPO = Path(__file__).resolve().parents[2]
SHARED = Path(os.environ.get("LM_SHARED_DIR") or REPO.parent / "shared")
SCENE = SHARED / "data/cave-256/cd_256"
MODEL = REPO / "models/demo/rt16nc-lmmse.safetensors"
CLI = Path(os.environ.get("LUMOSAIC_CLI") or REPO / "build/lumosaic")
THREADS = 2

need_scene = pytest.mark.skipif(not SCENE.is_dir(), reason=f"{SCENE} not found")


def need_cli():
    if "LUMOSAIC_CLI" in os.environ:
        assert CLI.is_file(), f"LUMOSAIC_CLI={CLI} does not exist"
    elif not CLI.is_file():
        pytest.skip(f"{CLI} not built")


def run_cli(*args):
    r = subprocess.run([str(CLI), *map(str, args)], capture_output=True, text=True)
    assert r.returncode == 0, f"lumosaic {' '.join(map(str, args))}: {r.stderr}"
    return r


def rss_kb() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    raise RuntimeError("no VmRSS")


@pytest.fixture(scope="module")
def model():
    return lumosaic.Model(MODEL, threads=THREADS)


@pytest.fixture(scope="module")
def truth():
    if not SCENE.is_dir():
        pytest.skip(f"{SCENE} not found")
    return lumosaic.read_cube(SCENE)[:255]  # whole 3 x 4 tiles, as `simulate --crop`


# ---- version and reading -----------------------------------------------------------------
def test_version_is_the_librarys():
    header = (REPO / "include/lumosaic.h").read_text()
    parts = [re.search(rf"#define LM_API_VERSION_{k} (\d+)", header).group(1)
             for k in ("MAJOR", "MINOR", "PATCH")]
    assert lumosaic.__version__ == ".".join(parts)


@need_scene
def test_read_cube_is_a_view_of_the_librarys_cube():
    cube, wl = lumosaic.read_cube(SCENE, return_wavelengths=True)
    assert cube.shape == (256, 256, 31) and cube.dtype == np.float32
    np.testing.assert_array_equal(wl, np.arange(400, 701, 10, dtype=np.float32))
    # band-major underneath, no copy: the (31, H, W) buffer is C-contiguous
    assert np.moveaxis(cube, -1, 0).flags.c_contiguous
    assert not cube.flags.owndata
    assert 0.0 <= float(cube.min()) and float(cube.max()) <= 1.5


@need_scene
def test_write_read_round_trip(tmp_path, truth):
    lumosaic.write_cube(tmp_path / "c.exr", truth)
    back, wl = lumosaic.read_cube(tmp_path / "c.exr", return_wavelengths=True)
    np.testing.assert_array_equal(back, truth)
    np.testing.assert_array_equal(wl, np.arange(400, 701, 10))
    # the wavelengths are written: another grid is read back resampled to 400-700 nm
    lumosaic.write_cube(tmp_path / "g.exr", truth, wavelengths=np.linspace(410, 690, 31))
    back, wl = lumosaic.read_cube(tmp_path / "g.exr", return_wavelengths=True)
    np.testing.assert_array_equal(wl, np.arange(400, 701, 10))
    assert not np.array_equal(back, truth)
    # a pixel-major (copied) cube writes the same values
    lumosaic.write_cube(str(tmp_path / "d.exr"), np.ascontiguousarray(truth))
    np.testing.assert_array_equal(lumosaic.read_cube(tmp_path / "d.exr"), truth)


def test_reads_mat_files_in_the_helper():
    # .mat files are read by the helper program installed beside the library
    assert (Path(lumosaic.__file__).parent / "lumosaic-reader").is_file()
    for name in ("kaust_v5.mat", "arad_v73.mat"):
        cube = lumosaic.read_cube(REPO / "tests/fuzz/corpus/mat" / name)
        assert cube.shape == (2, 3, 31)
        assert np.isfinite(cube).all()


# ---- equal to the commands ---------------------------------------------------------------
@need_scene
def test_simulate_and_reconstruct_equal_the_cli(tmp_path, model, truth):
    need_cli()
    run_cli("simulate", "--input", SCENE, "--output", tmp_path / "sim", "--crop", "--noise",
            0.05, "--seed", 3, "--format", "exr", "--threads", THREADS)
    run_cli("infer", "--model", MODEL, "--input", tmp_path / "sim/frames/frame_0000.exr",
            "--output", tmp_path / "inf", "--threads", THREADS)
    cli_truth = lumosaic.read_cube(tmp_path / "sim/gt/gt_0000.exr")
    np.testing.assert_array_equal(cli_truth, truth)
    cli_cube = lumosaic.read_cube(tmp_path / "inf/cube_0000.exr")

    frame = lumosaic.simulate(truth, noise=0.05, seed=3, threads=THREADS)
    assert frame.shape == (255, 256) and frame.dtype == np.float32
    cube = model.reconstruct(frame)
    assert cube.shape == (255, 256, 31) and cube.dtype == np.float32
    np.testing.assert_array_equal(cube, cli_cube)  # bit for bit
    np.testing.assert_array_equal(model.wavelengths, np.arange(400, 701, 10))
    score = lumosaic.metrics(cube, truth)
    assert 25 < score.psnr < 60 and 0.5 < score.ssim <= 1 and score.sam > 0

    # the sRGB preview: infer's srgb_0000.png (8 bits) to within its rounding
    mpl_image = pytest.importorskip("matplotlib.image")
    png = mpl_image.imread(tmp_path / "inf/srgb_0000.png")[..., :3]
    rgb = lumosaic.srgb(cube)
    assert rgb.shape == (255, 256, 3)
    assert np.abs(rgb * 255 - png * 255).max() <= 0.5 + 1e-3

    # another seed: another frame; the same seed again: the same frame
    assert not np.array_equal(lumosaic.simulate(truth, noise=0.05, seed=4, threads=THREADS),
                              frame)
    np.testing.assert_array_equal(
        lumosaic.simulate(truth, noise=0.05, seed=3, threads=THREADS), frame)


@need_scene
def test_bf16_equals_the_cli(tmp_path, truth):
    need_cli()
    run_cli("simulate", "--input", SCENE, "--output", tmp_path / "sim", "--crop", "--noise",
            0.05, "--format", "exr", "--threads", THREADS)
    run_cli("infer", "--model", MODEL, "--input", tmp_path / "sim/frames/frame_0000.exr",
            "--output", tmp_path / "inf", "--threads", THREADS, "--precision", "bf16")
    frame = lumosaic.simulate(truth, noise=0.05, threads=THREADS)
    with lumosaic.Model(MODEL, threads=THREADS, precision="bf16") as m:
        cube = m.reconstruct(frame)
    np.testing.assert_array_equal(cube, lumosaic.read_cube(tmp_path / "inf/cube_0000.exr"))


VIDEO_SCENE = SHARED / "data/cave/balloons_crop100"


def read_png16(path):
    image = pytest.importorskip("PIL.Image")
    with image.open(path) as im:
        a = np.array(im)
    assert a.dtype == np.uint16, f"{path}: {a.dtype}"
    return a


@pytest.mark.skipif(not VIDEO_SCENE.is_dir(), reason=f"{VIDEO_SCENE} not found")
def test_reconstruct_sequence_equals_the_cli(tmp_path, model):
    """A translating 3-frame video: aligned and unaligned cubes bit for bit infer's."""
    need_cli()
    run_cli("simulate", "--input", VIDEO_SCENE, "--output", tmp_path / "mv", "--crop",
            "--video", "--frames", 3, "--motion", "translate:150,-60")
    frames = [read_png16(tmp_path / f"mv/frames/frame_{i:04d}.png") for i in range(3)]
    err = run_cli("infer", "--model", MODEL, "--input", tmp_path / "mv/frames", "--output",
                  tmp_path / "al", "--threads", THREADS).stderr
    assert re.search(r"alignment [0-9.]+ s", err), err
    run_cli("infer", "--model", MODEL, "--input", tmp_path / "mv/frames", "--output",
            tmp_path / "na", "--threads", THREADS, "--no-align")
    cubes = model.reconstruct_sequence(frames)
    h, w = frames[0].shape
    assert cubes.shape == (3, h, w, 31) and cubes.dtype == np.float32
    plain = model.reconstruct_sequence(np.stack(frames), align=False)
    for i in range(3):
        name = f"cube_{i:04d}.exr"
        np.testing.assert_array_equal(cubes[i], lumosaic.read_cube(tmp_path / "al" / name))
        np.testing.assert_array_equal(plain[i], lumosaic.read_cube(tmp_path / "na" / name))
    assert not np.array_equal(cubes[1], plain[1])
    # one frame: the frame as reconstruct gives it
    np.testing.assert_array_equal(model.reconstruct_sequence(frames[:1])[0],
                                  model.reconstruct(frames[0]))


def test_reconstruct_sequence_errors(model):
    f = np.zeros((66, 64), np.float32)
    with pytest.raises(lumosaic.Error) as e:
        model.reconstruct_sequence([])
    assert e.value.status == lumosaic.Status.ARG
    with pytest.raises(lumosaic.Error) as e:
        model.reconstruct_sequence([f, np.zeros((72, 64), np.float32)])
    assert e.value.status == lumosaic.Status.SHAPE and "frames[1]" in str(e.value)
    with pytest.raises(lumosaic.Error) as e:
        model.reconstruct_sequence([f, f], bucket0=[f, f])  # a one-bucket model
    assert e.value.status == lumosaic.Status.ARG and "pass no bucket0" in str(e.value)
    bad = f.copy()
    bad[3, 4] = np.nan
    with pytest.raises(lumosaic.Error) as e:
        model.reconstruct_sequence([f, bad])
    assert e.value.status == lumosaic.Status.NUMERIC and "frame 1" in str(e.value)
    assert "\n" not in str(e.value)


def test_auto_and_bundled_models(tmp_path):
    with pytest.raises(lumosaic.Error) as e:
        lumosaic.Model.bundled(buckets=3)
    assert e.value.status == lumosaic.Status.ARG
    with pytest.raises(lumosaic.Error) as e:
        lumosaic.Model.auto(tmp_path / "missing.json")
    assert e.value.status == lumosaic.Status.IO and "missing.json" in str(e.value)
    with pytest.raises(lumosaic.Error) as e:
        lumosaic.Model.auto(tmp_path / "missing.json", tol=-1)
    assert e.value.status == lumosaic.Status.ARG
    calib = tmp_path / "auto.json"
    calib.write_text(
        '{"version": 1, "measure": "grad", "window": [66, 64], "stride": [30, 32], '
        '"edges": [0.02], "windows": [10, 10], "models": ['
        f'{{"model": "{MODEL}", "preset": "rt-16-nc+lmmse", "cost_s_per_window": 1, '
        '"macs_per_window": 1, "psnr": [30, 40]}, '
        f'{{"model": "{MODEL}", "preset": "rt-16-nc+lmmse", "cost_s_per_window": 2, '
        '"macs_per_window": 2, "psnr": [40, 40]}]}')
    with lumosaic.Model.auto(calib, tol=0.5, threads=THREADS) as m:
        assert m.preset == "auto" and m.buckets == 1
        frame = np.random.default_rng(0).random((132, 128), dtype=np.float32)
        cube = m.reconstruct(frame)
        assert cube.shape == (132, 128, 31)
        np.testing.assert_array_equal(m.reconstruct_sequence([frame])[0], cube)
        small = m.reconstruct(frame[:30, :32].copy())  # below one calibrated window
        assert small.shape == (30, 32, 31) and np.isfinite(small).all()
    b2 = REPO / "models/demo/tn96nc-b2-lmmseb2.safetensors"
    calib.write_text(calib.read_text().replace(f'"model": "{MODEL}", "preset": "rt-16-nc+lmmse", '
                                               '"cost_s_per_window": 2',
                                               f'"model": "{b2}", "preset": "tn-96-nc-b2+lmmse-b2", '
                                               '"cost_s_per_window": 2'))
    with pytest.raises(lumosaic.Error) as e:  # a two-bucket model beside a one-bucket one
        lumosaic.Model.auto(calib, tol=0.5, threads=THREADS)
    msg = str(e.value)
    assert e.value.status == lumosaic.Status.ARG and "read the same buckets" in msg
    assert "--" not in msg, msg
    # a calibration of two-bucket models reads both buckets
    calib.write_text(calib.read_text().replace(f'"model": "{MODEL}", "preset": "rt-16-nc+lmmse"',
                                               f'"model": "{b2}", "preset": "tn-96-nc-b2+lmmse-b2"'))
    with lumosaic.Model.auto(calib, tol=0.5, threads=THREADS) as m:
        assert m.preset == "auto" and m.buckets == 2
        f0 = np.random.default_rng(1).random((66, 64), dtype=np.float32)
        f1 = np.random.default_rng(2).random((66, 64), dtype=np.float32)
        cube = m.reconstruct(f1, bucket0=f0)
        assert cube.shape == (66, 64, 31) and np.isfinite(cube).all()
        with pytest.raises(lumosaic.Error) as e:
            m.reconstruct(f1)
        assert e.value.status == lumosaic.Status.ARG and "bucket0" in str(e.value)
    try:
        m = lumosaic.Model.bundled(buckets=1, threads=THREADS)
    except lumosaic.Error as e:
        pytest.skip(f"no bundled model: {e}")
    with m:
        assert m.buckets == 1 and m.preset != "auto"
    with lumosaic.Model.bundled(buckets=2, threads=THREADS) as m2:
        assert m2.buckets == 2
        f = np.zeros((66, 64), np.float32)
        for call in (lambda: m2.reconstruct(f), lambda: m2.reconstruct_sequence([f])):
            with pytest.raises(lumosaic.Error) as e:
                call()
            assert e.value.status == lumosaic.Status.ARG and "pass bucket0=" in str(e.value)


@need_scene
def test_average_of_a_model_with_itself_is_the_model(tmp_path, model, truth):
    out = tmp_path / "self.safetensors"
    lumosaic.average([MODEL, MODEL], out)
    frame = lumosaic.simulate(truth, noise=0.0)
    with lumosaic.Model(out, threads=THREADS) as soup:
        np.testing.assert_array_equal(soup.reconstruct(frame), model.reconstruct(frame))
    with pytest.raises(lumosaic.Error, match="one preset"):
        lumosaic.average([MODEL, REPO / "models/demo/tn160nc-lmmse.safetensors"], out)
    with pytest.raises(lumosaic.Error, match="2 to 64"):
        lumosaic.average([MODEL], out)


def test_convert_to_fp16_halves_the_file(tmp_path, model, truth):
    out = tmp_path / "h.safetensors"
    lumosaic.convert(MODEL, out)
    assert 2 * out.stat().st_size < MODEL.stat().st_size + 8192
    frame = lumosaic.simulate(truth, noise=0.0)
    with lumosaic.Model(out, threads=THREADS) as half:
        got, want = half.reconstruct(frame), model.reconstruct(frame)
    assert 0 < np.abs(got - want).max() < 2e-3
    back = tmp_path / "back.safetensors"
    lumosaic.convert(out, back, dtype="f32")
    assert back.stat().st_size == MODEL.stat().st_size
    with pytest.raises(ValueError, match="bf16"):
        lumosaic.convert(MODEL, out, dtype="bf16")
    with pytest.raises(lumosaic.Error, match="being converted"):
        lumosaic.convert(out, out)


def test_metrics_as_defined(model, truth):
    """The library's metrics (the code `lumosaic eval` scores with) against their definitions
    in numpy: the binding hands over the bands in the right order, whatever the layout."""
    cube = model.reconstruct(lumosaic.simulate(truth, noise=0.05, threads=THREADS))
    score = lumosaic.metrics(cube, truth)
    p, t = cube.astype(np.float64), truth.astype(np.float64)
    assert score.psnr == pytest.approx(10 * np.log10(1 / np.mean((p - t) ** 2)), abs=1e-3)
    assert score.mae == pytest.approx(np.mean(np.abs(p - t)), rel=1e-4)
    dot = (p * t).sum(-1)
    norm = np.linalg.norm(p, axis=-1) * np.linalg.norm(t, axis=-1)
    keep = np.linalg.norm(t, axis=-1) > 0
    cos = np.clip(dot[keep] / np.maximum(norm[keep], 1e-30), -1, 1)
    assert score.sam == pytest.approx(np.degrees(np.arccos(cos)).mean(), abs=0.05)
    assert 0.5 < score.ssim < 1
    # pixel-major copies: the same numbers
    assert lumosaic.metrics(np.ascontiguousarray(cube), np.ascontiguousarray(truth)) == score
    assert lumosaic.metrics(truth, truth).ssim == pytest.approx(1.0)


@need_scene
def test_uint16_frames_and_noise_given(model, truth):
    frame = lumosaic.simulate(truth, noise=Noise16(), seed=1, threads=THREADS)
    u16 = np.round(frame * 65535).astype(np.uint16)
    a = model.reconstruct(u16)
    b = model.reconstruct(u16.astype(np.float32) / np.float32(65535))
    np.testing.assert_array_equal(a, b)
    # float64 is taken too (converted)
    np.testing.assert_array_equal(model.reconstruct(frame.astype(np.float64)),
                                  model.reconstruct(frame))
    # a given noise level: another cube, as good
    c = model.reconstruct(frame, noise=0.0)
    assert not np.array_equal(c, model.reconstruct(frame))
    assert lumosaic.metrics(c, truth).psnr > lumosaic.metrics(a, truth).psnr - 1.0


def Noise16():
    return lumosaic.Noise(gauss_k=0.02, bits=16, clip=True)


@need_scene
def test_simulate_bucket0(truth):
    b1, b0 = lumosaic.simulate(truth, bucket0=True, threads=THREADS)
    assert b1.shape == b0.shape == truth.shape[:2]
    np.testing.assert_array_equal(b1, lumosaic.simulate(truth, threads=THREADS))
    assert 0 < float(b0.mean()) and not np.array_equal(b0, b1)
    sys_ = lumosaic.System()
    assert sys_.leds > 1 and sys_.tile == (3, 4)


# ---- errors --------------------------------------------------------------------------------
def test_errors_are_exceptions_with_one_line(tmp_path, model):
    with pytest.raises(lumosaic.Error) as e:
        lumosaic.Model(tmp_path / "missing.safetensors")
    assert "missing.safetensors" in str(e.value) and "\n" not in str(e.value)
    assert e.value.status == lumosaic.Status.IO and isinstance(e.value, Exception)
    with pytest.raises(lumosaic.Error) as e:
        lumosaic.read_cube(tmp_path / "nothing.exr")
    assert "nothing.exr" in str(e.value)
    with pytest.raises(lumosaic.Error) as e:
        model.reconstruct(np.zeros((127, 128), np.float32))  # not whole 3 x 4 tiles
    assert e.value.status == lumosaic.Status.SHAPE and "tile" in str(e.value)
    small = np.random.default_rng(1).random((30, 32), dtype=np.float32)  # below one window
    assert np.isfinite(model.reconstruct(small)).all()
    with pytest.raises(lumosaic.Error) as e:
        model.reconstruct(np.zeros((6, 32), np.float32))  # two tiles high
    assert e.value.status == lumosaic.Status.SHAPE and "3 x 3 mosaic tiles" in str(e.value)
    with pytest.raises(lumosaic.Error):
        model.reconstruct(np.zeros((3, 66, 64), np.float32))
    with pytest.raises(lumosaic.Error) as e:
        model.reconstruct(np.zeros((66, 64), np.int32))
    assert "dtype" in str(e.value)
    with pytest.raises(lumosaic.Error) as e:
        model.reconstruct(np.zeros((66, 64), np.float32), bucket0=np.zeros((66, 64)))
    assert "pass no bucket0" in str(e.value) and "->" not in str(e.value)
    with pytest.raises(lumosaic.Error) as e:
        model.reconstruct(np.zeros((66, 64), np.float32), noise=3.0)
    assert e.value.status == lumosaic.Status.ARG
    for bad in (-1.0, float("nan")):  # None, not a negative level, asks for the estimate
        with pytest.raises(lumosaic.Error) as e:
            model.reconstruct_sequence([np.zeros((66, 64), np.float32)], noise=bad)
        assert e.value.status == lumosaic.Status.ARG and "None" in str(e.value)
    with pytest.raises(lumosaic.Error) as e:
        lumosaic.simulate(np.zeros((0, 8, 31), np.float32))
    assert e.value.status == lumosaic.Status.SHAPE and "(0, 8, 31)" in str(e.value)
    with pytest.raises(lumosaic.Error) as e:
        lumosaic.simulate(np.zeros((6, 8, 32), np.float32))
    assert "32 bands" in str(e.value) and "400-700" in str(e.value)
    assert "lm_" not in str(e.value)  # no function of the C library in a Python message
    with pytest.raises(lumosaic.Error):
        lumosaic.Model(MODEL, precision="fp16")
    with pytest.raises(lumosaic.Error):
        lumosaic.Model(MODEL, threads=-1)
    with pytest.raises(lumosaic.Error):
        lumosaic.write_cube(tmp_path / "neg.exr", -np.ones((4, 4, 31), np.float32))
    with pytest.raises(lumosaic.Error):
        lumosaic.write_cube("/nonexistent/dir/x.exr", np.ones((4, 4, 31), np.float32))
    with pytest.raises(lumosaic.Error):
        lumosaic.metrics(np.zeros((16, 16, 31)), np.zeros((16, 17, 31)))
    nan = np.full((66, 64), 0.5, np.float32)
    nan[1, 2] = np.nan
    with pytest.raises(lumosaic.Error) as e:
        model.reconstruct(nan)
    assert e.value.status == lumosaic.Status.NUMERIC and "row 1, column 2" in str(e.value)
    with pytest.raises(lumosaic.Error) as e:
        lumosaic.metrics(np.full((16, 16, 31), np.nan), np.ones((16, 16, 31)))
    assert e.value.status == lumosaic.Status.NUMERIC
    with pytest.raises(lumosaic.Error) as e:
        lumosaic.simulate(np.full((12, 12, 31), np.inf, np.float32))
    assert e.value.status == lumosaic.Status.NUMERIC
    with pytest.raises(lumosaic.Error):
        lumosaic.simulate(np.ones((12, 12, 31), np.float32), system=tmp_path / "no.json")
    # the model still works after its errors
    out = model.reconstruct(np.full((66, 64), 0.5, np.float32))
    assert out.shape == (66, 64, 31) and np.isfinite(out).all()
    # a closed model says so
    m = lumosaic.Model(MODEL, threads=1)
    m.close()
    with pytest.raises(lumosaic.Error, match="closed"):
        m.reconstruct(np.zeros((66, 64), np.float32))


def hostile_files():
    files = sorted((REPO / "tests/fuzz/regress").glob("*/*"))
    rel = SHARED / "reliability"
    if rel.is_dir():
        files += sorted(p for p in rel.iterdir() if p.suffix != ".md")
    return files


def test_hostile_files_are_errors_not_crashes():
    files = hostile_files()
    assert len(files) >= 10
    for p in files:
        with pytest.raises(lumosaic.Error) as e:
            if p.suffix == ".safetensors":
                lumosaic.Model(p)
            else:
                lumosaic.read_cube(p)
        assert str(e.value) and "\n" not in str(e.value), p


# ---- the GIL, threads, memory ---------------------------------------------------------------
def test_gil_released_during_reconstruction():
    m = lumosaic.Model(MODEL, threads=1)
    rng = np.random.default_rng(1)
    frame = rng.random((480, 512), dtype=np.float32)
    m.reconstruct(frame)  # warm-up
    ticks = []
    stop = threading.Event()

    def count():
        while not stop.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.001)

    t = threading.Thread(target=count)
    t.start()
    time.sleep(0.05)
    t0 = time.perf_counter()
    m.reconstruct(frame)
    t1 = time.perf_counter()
    stop.set()
    t.join()
    d = t1 - t0
    assert d > 0.05, "the reconstruction is too short to tell"
    # the thread kept running in the middle half of the call (with the GIL held it would not
    # run at all between the call's start and its end)
    middle = [x for x in ticks if t0 + d / 4 <= x <= t1 - d / 4]
    assert len(middle) >= 3, (len(middle), len(ticks), d)


def test_threads_share_a_model_safely():
    m = lumosaic.Model(MODEL, threads=1)
    frame = np.random.default_rng(2).random((66, 64), dtype=np.float32)
    want = m.reconstruct(frame)
    got = [None] * 4

    def run(i):
        got[i] = m.reconstruct(frame)

    ts = [threading.Thread(target=run, args=(i,)) for i in range(4)]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    for g in got:
        np.testing.assert_array_equal(g, want)


def test_memory_returned_over_200_reconstructions():
    m = lumosaic.Model(MODEL, threads=1)
    frame = np.random.default_rng(3).random((96, 128), dtype=np.float32)
    for _ in range(20):  # warm-up: the model's working memory, numpy's caches
        m.reconstruct(frame)
    before = rss_kb()
    for _ in range(200):
        cube = m.reconstruct(frame)
        assert cube.shape == (96, 128, 31)
    grown = rss_kb() - before
    # one cube is 1.5 MB: 200 kept would be 300 MB; the bound is a few cubes' worth
    assert grown < 8 * 1024, f"RSS grew by {grown} kB over 200 reconstructions"
    # models loaded and closed return their memory too
    before = rss_kb()
    for _ in range(20):
        lumosaic.Model(MODEL, threads=1).close()
    assert rss_kb() - before < 8 * 1024


@need_scene
def test_cubes_freed_with_their_last_view():
    lib = lumosaic._capi.lib
    free = lib.lm_api_cube_free
    freed = []
    lib.lm_api_cube_free = lambda h: (freed.append(h), free(h))
    try:
        cube = lumosaic.read_cube(SCENE)
        part = cube[10:20, 5:9]
        del cube
        assert not freed  # a view still holds the library's buffer
        assert float(part.sum()) > 0
        del part
        assert len(freed) == 1
    finally:
        lib.lm_api_cube_free = free
    # 20 reads of an 8 MB cube, dropped: a leak would keep 160 MB
    before = rss_kb()
    for _ in range(20):
        lumosaic.read_cube(SCENE)
    assert rss_kb() - before < 32 * 1024


# ---- the example -------------------------------------------------------------------------
@need_scene
def test_example_script(tmp_path):
    pytest.importorskip("matplotlib")
    out = tmp_path / "spectrum.png"
    r = subprocess.run([sys.executable, str(REPO / "examples/spectrum.py"), str(SCENE),
                        str(out)], capture_output=True, text=True,
                       env={**os.environ, "MPLBACKEND": "Agg"}, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    psnr = float(re.search(r"PSNR ([0-9.]+) dB", r.stdout).group(1))
    assert 25 < psnr < 60
    assert out.stat().st_size > 20000
    import matplotlib.image
    img = matplotlib.image.imread(out)
    assert img.shape[1] > 1000 and img.std() > 0.05  # a drawn figure, not a blank page
