"""Lumosaic: 31-band hyperspectral cubes (400-700 nm) from coded camera frames, and coded
frames from cubes, for numpy.

The functions call the Lumosaic C library (``include/lumosaic.h``, the code behind the
``lumosaic`` program: a frame reconstructed here equals ``lumosaic infer``'s cube) through
ctypes, which releases the GIL during each call, so other Python threads run while a frame is
reconstructed.

Arrays:

- a frame is a ``(height, width)`` array: ``float32`` (1.0 = full scale; other float types are
  converted) or ``uint16`` (65535 = full scale, a 16-bit PNG or TIFF's samples);
- a cube is a ``(height, width, bands)`` array, ``float32``, with one wavelength (nm) per band.
  Cubes the library returns are views of its band-major ``(bands, height, width)`` buffers
  (no copy); ``numpy.ascontiguousarray`` gives a pixel-major copy when one is needed.

Errors of the library, and arguments it cannot take, raise :class:`Error` with the library's
one-line message and a :class:`Status`.

What it is not: training, evaluation over datasets, or reading frame files (the ``lumosaic``
program's ``train``, ``eval`` and ``infer`` on files).

Example::

    import lumosaic
    truth = lumosaic.read_cube("cave-256/cd_256")          # (256, 256, 31)
    frame = lumosaic.simulate(truth, noise=0.05)           # (256, 256) coded frame
    model = lumosaic.Model("models/demo/rt16nc-lmmse.safetensors")
    cube = model.reconstruct(frame)                        # (256, 256, 31)
    print(lumosaic.metrics(cube, truth).psnr)
"""
from __future__ import annotations

import ctypes
import os
import threading
from dataclasses import dataclass
from typing import NamedTuple, Optional, Sequence, Tuple, Union

import numpy as np

from . import _capi
from ._capi import Error, Status

__all__ = ["Error", "Status", "Noise", "Metrics", "System", "Model", "simulate", "read_cube",
           "write_cube", "srgb", "metrics", "average", "convert", "__version__"]

#: The library's API version ("MAJOR.MINOR.PATCH", from ``lm_api_version``).
__version__: str = _capi.version()

PathLike = Union[str, "os.PathLike[str]"]


def _path(p: PathLike) -> bytes:
    return os.fsencode(p)


def _threads(threads: Optional[int]) -> int:
    if threads is None:
        return 0
    if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)):
        raise Error(Status.ARG, f"threads {threads!r}: an integer (or None for all cores)")
    return int(threads)


# ---- cubes ---------------------------------------------------------------------------------
class _CubeOwner:
    """A library-owned cube whose values numpy arrays view; freed with the last of them."""

    def __init__(self, handle: ctypes.c_void_p) -> None:
        self._handle = handle
        b, h, w = ctypes.c_int(), ctypes.c_int(), ctypes.c_int()
        _capi.call("cube_shape", handle, ctypes.byref(b), ctypes.byref(h), ctypes.byref(w))
        self.shape = (b.value, h.value, w.value)
        ptr = _capi.lib.lm_api_cube_data(handle)
        self.__array_interface__ = {"shape": self.shape, "typestr": "<f4",
                                    "data": (ptr, False), "version": 3}
        wl = _capi.lib.lm_api_cube_wavelengths(handle)
        self.wavelengths = np.ctypeslib.as_array(
            ctypes.cast(wl, ctypes.POINTER(ctypes.c_float)), (b.value,)).copy()

    def __del__(self) -> None:
        handle, self._handle = getattr(self, "_handle", None), None
        if handle and _capi is not None and _capi.lib is not None:
            _capi.lib.lm_api_cube_free(handle)


def _as_cube(cube: np.ndarray, what: str) -> np.ndarray:
    """A (height, width, bands) float array, checked."""
    a = np.asarray(cube)
    if a.ndim != 3:
        raise Error(Status.SHAPE, f"{what}: shape {a.shape}: a (height, width, bands) array")
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise Error(Status.ARG, f"{what}: dtype {a.dtype}: a float array")
    if a.size == 0:
        raise Error(Status.SHAPE, f"{what}: shape {a.shape}: every size at least 1")
    return a


def _new_cube(cube: np.ndarray, wavelengths: Optional[Sequence[float]], what: str):
    """A library cube holding a copy of cube (height, width, bands); the caller frees it."""
    a = _as_cube(cube, what)
    h, w, b = a.shape
    wl = None
    if wavelengths is not None:
        wla = np.ascontiguousarray(wavelengths, dtype=np.float32)
        if wla.shape != (b,):
            raise Error(Status.SHAPE, f"{what}: {wla.size} wavelengths for {b} bands")
        wl = wla.ctypes.data_as(ctypes.POINTER(ctypes.c_float))
    handle = ctypes.c_void_p()
    _capi.call("cube_create", b, h, w, wl, ctypes.byref(handle))
    try:
        dst = np.asarray(_View(handle, (b, h, w)))
        dst[...] = np.moveaxis(a, -1, 0)
    except BaseException:
        _capi.lib.lm_api_cube_free(handle)
        raise
    return handle


class _View:
    """A non-owning numpy view of a library cube's values (the cube must outlive it)."""

    def __init__(self, handle: ctypes.c_void_p, shape: Tuple[int, int, int]) -> None:
        self.__array_interface__ = {"shape": shape, "typestr": "<f4", "version": 3,
                                    "data": (_capi.lib.lm_api_cube_data(handle), False)}


def read_cube(path: PathLike, mat_key: Optional[str] = None, *, return_wavelengths: bool = False
              ) -> Union[np.ndarray, Tuple[np.ndarray, np.ndarray]]:
    """Read a spectral cube: a CAVE folder (31 band PNGs), a MATLAB ``.mat`` file (v5 or v7.3:
    ARAD, KAUST, ICVL, Harvard and other keys) or a spectral OpenEXR (channels ``T.<nm>nm``).

    Cubes on 31 bands 400-700 nm (or the forward model's 41 bins 380-780 nm) are returned as
    read; other grids covering 420-680 nm are resampled to 31 bands 400-700 nm. A
    ``<path>.wavelengths.txt`` or ``.json`` sidecar overrides the file's wavelengths.

    Args:
        path: the file or folder.
        mat_key: the ``.mat`` variable holding the cube (None: the first of the usual keys).
        return_wavelengths: also return the wavelengths.

    Returns:
        The cube, a ``(height, width, bands)`` float32 view of the library's buffer (no copy),
        or ``(cube, wavelengths)`` with ``return_wavelengths`` (a ``(bands,)`` float32 array, nm).

    Raises:
        Error: a missing, unreadable or malformed file (a hostile file gives an error, not a
            crash: ``.mat`` files are read in a separate process).
    """
    handle = ctypes.c_void_p()
    _capi.call("cube_read", _path(path), mat_key.encode() if mat_key else None,
               ctypes.byref(handle))
    owner = _CubeOwner(handle)
    cube = np.asarray(owner).transpose(1, 2, 0)
    return (cube, owner.wavelengths.copy()) if return_wavelengths else cube


def write_cube(path: PathLike, cube: np.ndarray,
               wavelengths: Optional[Sequence[float]] = None) -> None:
    """Write a cube as a spectral OpenEXR (one float channel ``T.<nm>nm`` per band, lossless),
    atomically (a temporary file renamed into place).

    Args:
        path: the ``.exr`` file to write.
        cube: ``(height, width, bands)``; values finite and >= 0.
        wavelengths: ``bands`` values in nm (None: 400, 410, ... nm).

    Raises:
        Error: negative or non-finite values, or a file that cannot be written.
    """
    handle = _new_cube(cube, wavelengths, "write_cube")
    try:
        _capi.call("cube_write", _path(path), handle)
    finally:
        _capi.lib.lm_api_cube_free(handle)


def srgb(cube: np.ndarray, exposure: float = 1.0,
         wavelengths: Optional[Sequence[float]] = None) -> np.ndarray:
    """The sRGB preview of a reflectance cube, as ``lumosaic infer`` writes it
    (``srgb_NNNN.png``): each spectrum times ``exposure`` under D65 with the CIE 1931
    2-degree observer, clipped to [0, 1] and gamma-encoded.

    Args:
        cube: ``(height, width, bands)`` reflectance.
        exposure: a factor on the values (1 = as is).
        wavelengths: the cube's wavelengths in nm (None: 400, 410, ... nm).

    Returns:
        A ``(height, width, 3)`` float32 RGB image in [0, 1] (``matplotlib``'s ``imshow`` takes
        it as is).
    """
    handle = _new_cube(cube, wavelengths, "srgb")
    try:
        _, h, w = _shape(handle)
        rgb = np.empty((h, w, 3), np.float32)
        _capi.call("cube_srgb", handle, float(exposure), rgb.ctypes.data, rgb.size)
    finally:
        _capi.lib.lm_api_cube_free(handle)
    return rgb


# ---- systems and simulation ------------------------------------------------------------------
class System:
    """An imaging system (LEDs, sensor, mosaic tile): a JSON system description.

    Args:
        path: the description file (None: the bundled prototype's).
    """

    def __init__(self, path: Optional[PathLike] = None) -> None:
        self._handle = ctypes.c_void_p()
        _capi.call("system_load", _path(path) if path is not None else None,
                   ctypes.byref(self._handle))
        leds, tr, tc = ctypes.c_int(), ctypes.c_int(), ctypes.c_int()
        _capi.call("system_info", self._handle, ctypes.byref(leds), ctypes.byref(tr),
                   ctypes.byref(tc))
        #: the number of LEDs
        self.leds: int = leds.value
        #: the mosaic tile (rows, columns): frames to reconstruct are multiples of it
        self.tile: Tuple[int, int] = (tr.value, tc.value)

    def __del__(self) -> None:
        handle = getattr(self, "_handle", None)
        if handle and _capi is not None and _capi.lib is not None:
            _capi.lib.lm_api_system_free(handle)
            self._handle = None

    def __repr__(self) -> str:
        return f"System(leds={self.leds}, tile={self.tile})"


@dataclass
class Noise:
    """Sensor noise of a simulated frame, applied in this order (a zero field is off): shot
    noise (``photons``: photo-electrons at full scale), full-well clipping (``clip``), read
    noise (``read_noise``: electrons with shot noise, else a fraction of full scale), Gaussian
    noise with sd = ``gauss_k`` x the frame's largest clean value (0.05 = 5 %), clipping to
    [0, 1] (``clip``), quantisation to ``bits`` bits (1..24), as ``lumosaic simulate``'s
    ``--poisson``, ``--clip``, ``--read-noise``, ``--noise`` and ``--bits``."""

    gauss_k: float = 0.0
    photons: float = 0.0
    read_noise: float = 0.0
    clip: bool = False
    bits: int = 0


def simulate(cube: np.ndarray, system: Union[System, PathLike, None] = None,
             noise: Union[float, Noise] = 0.0, seed: int = 1, bucket0: bool = False,
             threads: Optional[int] = None, wavelengths: Optional[Sequence[float]] = None
             ) -> Union[np.ndarray, Tuple[np.ndarray, np.ndarray]]:
    """The coded frame a cube gives through the system's forward model, as
    ``lumosaic simulate --seed SEED --format exr`` makes it.

    Args:
        cube: ``(height, width, 31)`` reflectance on 400-700 nm (or the system's own grid, with
            ``wavelengths``); its top-left pixel is at tile phase (0, 0). Copied once into the
            library's band-major layout.
        system: a :class:`System`, a description file, or None for the bundled prototype.
        noise: Gaussian noise level (sd = noise x the frame's maximum) or a :class:`Noise`.
        seed: the noise seed.
        bucket0: also return bucket 0 (the light of every other LED) divided by LEDs - 1, as
            two-bucket models read it.
        threads: threads of the forward model (None: all cores).
        wavelengths: the cube's wavelengths in nm (None: 400, 410, ... nm).

    Returns:
        The ``(height, width)`` float32 frame (bucket 1), or ``(bucket1, bucket0)``.
    """
    sys_ = system if isinstance(system, System) else System(system)
    n = noise if isinstance(noise, Noise) else Noise(gauss_k=float(noise))
    ns = _capi.NoiseStruct(n.gauss_k, n.photons, n.read_noise, int(bool(n.clip)), int(n.bits))
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not \
            0 <= int(seed) < 2**64:
        raise Error(Status.ARG, f"seed {seed!r}: an integer 0..2^64-1")
    nt = _threads(threads)
    handle = _new_cube(cube, wavelengths, "simulate")
    try:
        _, h, w = _shape(handle)
        b1 = np.empty((h, w), np.float32)
        b0 = np.empty((h, w), np.float32) if bucket0 else None
        _capi.call("simulate", sys_._handle, handle, ctypes.byref(ns), int(seed), nt,
                   b1.ctypes.data, b0.ctypes.data if b0 is not None else None, h * w)
    finally:
        _capi.lib.lm_api_cube_free(handle)
    return (b1, b0) if bucket0 else b1


def average(models: Sequence[PathLike], output: PathLike) -> None:
    """Average the weights of trained models of one preset (and base) into one model file, as
    ``lumosaic average --output OUTPUT MODELS...`` does: checkpoints of one run, or runs forked
    from one checkpoint (a "model soup"). Every parameter becomes the models' mean; elements
    equal in all of them (a frozen base) are kept exactly. Load the result with :class:`Model`
    and score it against the models it came from.

    Args:
        models: 2 to 64 run folders or ``.safetensors`` files written by ``lumosaic train``, of
            one preset, base, system description, buckets and frames.
        output: the ``.safetensors`` file to write (atomically).

    Raises:
        Error: models of different presets or systems, unreadable files, an unwritable output.
    """
    paths = [_path(m) for m in models]
    arr = (ctypes.c_char_p * max(len(paths), 1))(*paths)
    _capi.call("model_average", arr, len(paths), _path(output))


def convert(model: PathLike, output: PathLike, dtype: str = "f16") -> None:
    """Rewrite a trained model with its weights stored as IEEE half precision (``"f16"``: half
    the file; each weight rounded once and widened back exactly when read, so reconstruction
    still computes in fp32) or as fp32 (``"f32"``), as ``lumosaic convert --output OUTPUT
    --dtype DTYPE MODEL`` does. The metadata is kept. Score the result against the model.

    Args:
        model: a run folder or ``.safetensors`` file written by ``lumosaic train``.
        output: the ``.safetensors`` file to write (atomically); not the model's own file.
        dtype: ``"f16"`` (default) or ``"f32"``.

    Raises:
        ValueError: another dtype.
        Error: a weight fp16 cannot hold, unreadable files, an unwritable output.
    """
    if dtype not in ("f16", "f32"):
        raise ValueError(f"dtype {dtype!r}: 'f16' or 'f32'")
    _capi.call("model_convert", _path(model), _path(output), 1 if dtype == "f16" else 0)


def _shape(handle) -> Tuple[int, int, int]:
    b, h, w = ctypes.c_int(), ctypes.c_int(), ctypes.c_int()
    _capi.call("cube_shape", handle, ctypes.byref(b), ctypes.byref(h), ctypes.byref(w))
    return b.value, h.value, w.value


# ---- models ----------------------------------------------------------------------------------
def _frame_array(a, what: str) -> np.ndarray:
    x = np.asarray(a)
    if x.ndim != 2:
        raise Error(Status.SHAPE, f"{what}: shape {x.shape}: a (height, width) frame")
    if x.dtype.kind == "u" and x.dtype.itemsize == 2:
        return np.ascontiguousarray(x, dtype=np.uint16)  # (native byte order)
    if np.issubdtype(x.dtype, np.floating):
        return np.ascontiguousarray(x, dtype=np.float32)
    raise Error(Status.ARG, f"{what}: dtype {x.dtype}: uint16 (65535 = full scale) or float "
                            "(1.0 = full scale)")


def _to_float(x: np.ndarray) -> np.ndarray:
    if x.dtype == np.uint16:  # as the library normalises 16-bit samples
        return x.astype(np.float32) / np.float32(65535.0)
    return x


def _noise_level(noise: Optional[float]) -> float:
    """The library's noise level: noise (0..1), or -1 (estimate it) for None."""
    if noise is None:
        return -1.0
    level = float(noise)
    if not 0.0 <= level <= 1.0:  # also NaN
        raise Error(Status.ARG, f"noise {noise!r}: a level 0..1 (sd as a fraction of the "
                                f"frame's maximum), or None to estimate it")
    return level


class Model:
    """A trained model with its system and its working memory.

    Args:
        path: a ``.safetensors`` file written by ``lumosaic train`` (e.g. the bundled
            ``models/demo/rt16nc-lmmse.safetensors``) or a training run folder.
        threads: threads of each reconstruction (None: all cores, as ``lumosaic infer``).
        precision: ``"fp32"`` (None, the default) or ``"bf16"`` (the convolution products'
            operands rounded to bf16, sums in fp32, as ``lumosaic infer --precision bf16``).
        system: the system description the model was trained with (None: the one recorded in
            the model file).
        patchwise: reconstruct in overlapping 66 x 64 windows even where the model could run
            on the whole frame at once (``lumosaic infer --tiles``).
        clamp: set values below 0 to 0, as ``lumosaic infer`` writes cubes (False: the values
            as the network returns them, as ``lumosaic eval`` scores them).

    One model runs one reconstruction at a time: calls from several threads wait for each other
    (use one model per thread to run them in parallel).
    """

    def __init__(self, path: PathLike, threads: Optional[int] = None,
                 precision: Optional[str] = None, system: Union[System, PathLike, None] = None,
                 patchwise: bool = False, clamp: bool = True) -> None:
        self._open(lambda sys_, h: _capi.call("model_load", _path(path), sys_, h), threads,
                   precision, system, patchwise, clamp)

    @classmethod
    def bundled(cls, buckets: int = 1, threads: Optional[int] = None,
                precision: Optional[str] = None, system: Union[System, PathLike, None] = None,
                patchwise: bool = False, clamp: bool = True) -> "Model":
        """The bundled model for frames of ``buckets`` buckets, as ``lumosaic infer --model
        auto`` picks it (from ``models/demo/`` of the source tree, or ``$LM_MODELS_DIR``).

        Args:
            buckets: 1 (bucket 1 only) or 2 (both buckets: ``reconstruct`` then needs
                ``bucket0``).
            threads, precision, system, patchwise, clamp: as for :class:`Model`.
        """
        if isinstance(buckets, bool) or not isinstance(buckets, (int, np.integer)):
            raise Error(Status.ARG, f"buckets {buckets!r}: 1 or 2")
        self = cls.__new__(cls)
        self._open(lambda sys_, h: _capi.call("model_load_bundled", int(buckets), sys_, h),
                   threads, precision, system, patchwise, clamp)
        return self

    @classmethod
    def auto(cls, calibration: PathLike, tol: float = 0.5, threads: Optional[int] = None,
             precision: Optional[str] = None, system: Union[System, PathLike, None] = None,
             clamp: bool = True) -> "Model":
        """A calibrated per-window choice of models, as ``lumosaic infer --model auto --auto
        FILE --auto-tol TOL``: each 66 x 64 window is reconstructed by the cheapest model whose
        expected PSNR is within ``tol`` dB of the best model's, and the windows are blended.

        Args:
            calibration: a file written by ``lumosaic fit-auto`` (one-frame models of one
                system that read the same buckets; for two-bucket models :attr:`buckets` is 2
                and :meth:`reconstruct` takes ``bucket0``).
            tol: the accuracy the choice may give up per window, in dB of expected PSNR (>= 0;
                0 = always the best model).
            threads, precision, system, clamp: as for :class:`Model` (such a model always runs
                patch-wise; its :attr:`preset` is ``"auto"``).
        """
        self = cls.__new__(cls)
        self._open(lambda sys_, h: _capi.call("model_load_auto", _path(calibration),
                                              float(tol), sys_, h),
                   threads, precision, system, False, clamp)
        return self

    def _open(self, load, threads, precision, system, patchwise, clamp) -> None:
        self._lock = threading.Lock()
        self._handle = ctypes.c_void_p()
        if precision not in (None, "fp32", "bf16"):
            raise Error(Status.ARG, f"precision {precision!r}: 'fp32' or 'bf16'")
        sys_ = None if system is None else system if isinstance(system, System) else \
            System(system)
        load(sys_._handle if sys_ else None, ctypes.byref(self._handle))
        preset, buckets, tr, tc = ctypes.c_char_p(), ctypes.c_int(), ctypes.c_int(), \
            ctypes.c_int()
        _capi.call("model_info", self._handle, ctypes.byref(preset), ctypes.byref(buckets),
                   ctypes.byref(tr), ctypes.byref(tc))
        #: the model's preset name, e.g. "rt-16-nc+lmmse" ("auto" for a calibrated choice)
        self.preset: str = preset.value.decode()
        #: the buckets it reads: 1, or 2 (``reconstruct`` then needs ``bucket0``)
        self.buckets: int = buckets.value
        #: the mosaic tile (rows, columns): frame sizes are multiples of it, at least 3 x 3
        #: tiles
        self.tile: Tuple[int, int] = (tr.value, tc.value)
        _capi.call("model_set_threads", self._handle, _threads(threads))
        _capi.call("model_set_precision", self._handle,
                   _capi.PRECISION_BF16 if precision == "bf16" else _capi.PRECISION_FP32)
        _capi.call("model_set_patchwise", self._handle, int(bool(patchwise)))
        _capi.call("model_set_clamp", self._handle, int(bool(clamp)))
        self._wavelengths = np.arange(400, 701, 10, dtype=np.float32)

    def _check_buckets(self, given: bool) -> None:
        if self.buckets == 2 and not given:
            raise Error(Status.ARG, f"model {self.preset} reads both buckets: pass bucket0= "
                                    "(bucket 0 of the same frame)")
        if self.buckets != 2 and given:
            raise Error(Status.ARG, f"model {self.preset} reads bucket 1 only: pass no bucket0")

    @property
    def wavelengths(self) -> np.ndarray:
        """The wavelengths (nm) of the reconstructed cubes' 31 bands: 400, 410, ..., 700."""
        return self._wavelengths.copy()

    def reconstruct(self, frame: np.ndarray, bucket0: Optional[np.ndarray] = None,
                    noise: Optional[float] = None) -> np.ndarray:
        """Reconstruct one coded frame, as ``lumosaic infer`` does.

        Args:
            frame: ``(height, width)`` coded frame (bucket 1), float (1.0 = full scale) or
                uint16 (65535 = full scale); height and width multiples of :attr:`tile`, at
                least 3 x 3 tiles (9 x 12). A C-contiguous float32 or uint16 array is read in
                place.
            bucket0: two-bucket models: bucket 0 of the same frame divided by LEDs - 1 (as
                :func:`simulate` gives it).
            noise: the frame's Gaussian noise level for models that read it (sd = noise x the
                frame's maximum); None estimates it from the frame (``lumosaic infer``'s
                default, ``--noise-level``).

        Returns:
            The cube, ``(height, width, 31)`` float32 on :attr:`wavelengths`: a view of a new
            band-major ``(31, height, width)`` array (``.base``), written by the library.
        """
        f1 = _frame_array(frame, "frame")
        f0 = None
        self._check_buckets(bucket0 is not None)
        if bucket0 is not None:
            f0 = _frame_array(bucket0, "bucket0")
            if f0.shape != f1.shape:
                raise Error(Status.SHAPE, f"bucket0: shape {f0.shape} is not the frame's "
                                          f"{f1.shape}")
            if f0.dtype != f1.dtype:
                f1, f0 = _to_float(f1), _to_float(f0)
        level = _noise_level(noise)
        h, w = f1.shape
        out = np.empty((31, h, w), np.float32)
        wl = np.empty(31, np.float32)
        fr = _capi.Frame(h, w, _capi.PIXEL_U16 if f1.dtype == np.uint16 else _capi.PIXEL_F32,
                         f1.ctypes.data, f0.ctypes.data if f0 is not None else None)
        with self._lock:
            if not self._handle:
                raise Error(Status.ARG, "the model is closed")
            _capi.call("model_set_noise_level", self._handle, level)
            _capi.call("reconstruct", self._handle, ctypes.byref(fr), out.ctypes.data,
                       out.size, wl.ctypes.data)
        self._wavelengths = wl
        return out.transpose(1, 2, 0)

    def reconstruct_sequence(self, frames: Sequence[np.ndarray],
                             bucket0: Optional[Sequence[np.ndarray]] = None, align: bool = True,
                             noise: Optional[float] = None) -> np.ndarray:
        """Reconstruct a sequence of coded frames (a video, in time order), as ``lumosaic
        infer`` does with a folder of frames.

        Args:
            frames: ``N`` coded frames of one size (a sequence of ``(height, width)`` arrays or
                an ``(N, height, width)`` array), float (1.0 = full scale) or uint16 (65535 =
                full scale), as for :meth:`reconstruct`.
            bucket0: two-bucket models: bucket 0 of each frame (the same count and size); such
                sequences are reconstructed without alignment (bucket 0 is not aligned in time).
            align: for 2 or more frames, move each LED sub-image of a frame to the frame's
                lime-LED time by optical flow to the neighbouring frames (sub-images of at least
                24 x 24 pixels; smaller frames are reconstructed unaligned); False: as recorded
                (``lumosaic infer --no-align``). Multi-frame models ("-mf3") need 2 or more
                frames and read each frame with its neighbours.
            noise: as for :meth:`reconstruct`.

        Returns:
            The cubes, ``(N, height, width, 31)`` float32 on :attr:`wavelengths`: a view of a new
            ``(N, 31, height, width)`` array (``.base``), written by the library.
        """
        f1 = [_frame_array(f, f"frames[{i}]") for i, f in enumerate(frames)]
        if not f1:
            raise Error(Status.ARG, "frames: an empty sequence (at least 1 frame)")
        self._check_buckets(bucket0 is not None)
        f0 = None
        if bucket0 is not None:
            f0 = [_frame_array(f, f"bucket0[{i}]") for i, f in enumerate(bucket0)]
            if len(f0) != len(f1):
                raise Error(Status.SHAPE, f"bucket0: {len(f0)} frames, frames {len(f1)}")
        if len({f.dtype for f in f1 + (f0 or [])}) > 1:
            f1 = [_to_float(f) for f in f1]
            f0 = [_to_float(f) for f in f0] if f0 is not None else None
        for i, f in enumerate(f1):
            if f.shape != f1[0].shape or (f0 is not None and f0[i].shape != f.shape):
                raise Error(Status.SHAPE, f"frames[{i}]: shape {f.shape} is not frame 0's "
                                          f"{f1[0].shape} (or its bucket 0's)")
        level = _noise_level(noise)
        n, (h, w) = len(f1), f1[0].shape
        kind = _capi.PIXEL_U16 if f1[0].dtype == np.uint16 else _capi.PIXEL_F32
        arr = (_capi.Frame * n)(*[
            _capi.Frame(h, w, kind, f1[i].ctypes.data,
                        f0[i].ctypes.data if f0 is not None else None) for i in range(n)])
        out = np.empty((n, 31, h, w), np.float32)
        wl = np.empty(31, np.float32)
        with self._lock:
            if not self._handle:
                raise Error(Status.ARG, "the model is closed")
            _capi.call("model_set_noise_level", self._handle, level)
            _capi.call("reconstruct_sequence", self._handle, arr, n, int(bool(align)),
                       out.ctypes.data, out.size, wl.ctypes.data)
        self._wavelengths = wl
        return out.transpose(0, 2, 3, 1)

    def close(self) -> None:
        """Free the model now (otherwise when it is garbage collected)."""
        lock = getattr(self, "_lock", None)
        if lock is None:
            return
        with lock:
            handle, self._handle = getattr(self, "_handle", None), None
            if handle and _capi is not None and _capi.lib is not None:
                _capi.lib.lm_api_model_free(handle)

    def __enter__(self) -> "Model":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Model(preset={self.preset!r}, buckets={self.buckets}, tile={self.tile})"


# ---- metrics ---------------------------------------------------------------------------------
class Metrics(NamedTuple):
    """Scores of a reconstruction, as ``lumosaic eval`` reports them."""

    psnr: float  #: dB, peak 1, over every value
    ssim: float  #: 11 x 11 Gaussian window (sigma 1.5) per band, averaged
    mae: float  #: mean absolute error
    sam: float  #: mean spectral angle (degrees) over pixels with a non-zero true spectrum


def _band_major(a: np.ndarray, what: str) -> np.ndarray:
    x = _as_cube(a, what)
    return np.ascontiguousarray(np.moveaxis(x, -1, 0), dtype=np.float32)


def metrics(pred: np.ndarray, truth: np.ndarray) -> Metrics:
    """PSNR, SSIM, MAE and SAM of a reconstruction against the truth, computed by the library
    code ``lumosaic eval`` uses.

    Args:
        pred, truth: ``(height, width, bands)`` arrays of one shape (height and width at least
            11). Band-major views (as :meth:`Model.reconstruct` and :func:`read_cube` return)
            are read in place.
    """
    p = _band_major(pred, "pred")
    t = _band_major(truth, "truth")
    if p.shape != t.shape:
        raise Error(Status.SHAPE, f"metrics: pred {p.shape[1:] + p.shape[:1]} and truth "
                                  f"{t.shape[1:] + t.shape[:1]} differ in shape")
    m = _capi.MetricsStruct()
    b, h, w = p.shape
    _capi.call("metrics_compute", p.ctypes.data, t.ctypes.data, b, h, w, ctypes.byref(m))
    return Metrics(m.psnr, m.ssim, m.mae, m.sam)
