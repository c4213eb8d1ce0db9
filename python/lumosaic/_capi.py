"""The C library's declarations (include/lumosaic.h) for ctypes, and its errors as exceptions.

The library is loaded with ``ctypes.CDLL``, which releases the GIL for the duration of every
call: a reconstruction or a simulation runs while other Python threads go on.
What it is not: the package's interface (``lumosaic/__init__.py``: arrays, checks, ownership).
"""
from __future__ import annotations

import ctypes
import enum
import os
from ctypes import POINTER, c_char, c_char_p, c_double, c_float, c_int, c_size_t, c_uint64, c_void_p

_HERE = os.path.dirname(os.path.abspath(__file__))
LIBRARY_PATH = os.path.join(_HERE, "liblumosaic.so")

# The library finds its system descriptions and spectra in $LM_DATA_DIR: the copies installed
# with the package, unless the caller chose others.
if os.path.isdir(os.path.join(_HERE, "data", "systems")):
    os.environ.setdefault("LM_DATA_DIR", os.path.join(_HERE, "data"))


class Status(enum.IntEnum):
    """A status of the C library (lm_api_status): 0 is success, errors are negative."""

    OK = 0
    SHAPE = -1  #: sizes that do not fit (frame size, band count, buffers)
    ARG = -2  #: an invalid argument
    NOMEM = -3  #: out of memory
    IO = -4  #: a file that cannot be read (missing, no permission)
    FORMAT = -5  #: a file whose content is malformed or not what was expected
    BACKEND = -6  #: a compute backend failure
    NUMERIC = -7  #: NaN, inf or a negative value where one is not allowed
    UNSUPPORTED = -8  #: a valid request this library cannot serve
    WRITE = -9  #: an output that cannot be written (disk full, permissions)


class Error(Exception):
    """An error of the Lumosaic library: ``str(e)`` is its one-line message (naming the file or
    argument and the problem), ``e.status`` its :class:`Status`."""

    def __init__(self, status: int, message: str) -> None:
        try:
            self.status: Status | int = Status(status)
        except ValueError:
            self.status = status
        self.message = message
        super().__init__(message)


Error.__module__ = "lumosaic"
Status.__module__ = "lumosaic"


class _Error(ctypes.Structure):
    _fields_ = [("status", c_int), ("message", c_char * 512)]


class Frame(ctypes.Structure):
    _fields_ = [("height", c_int), ("width", c_int), ("type", c_int),
                ("bucket1", c_void_p), ("bucket0", c_void_p)]


class NoiseStruct(ctypes.Structure):
    _fields_ = [("gauss_k", c_double), ("photons", c_double), ("read_noise", c_double),
                ("clip", c_int), ("bits", c_int)]


class MetricsStruct(ctypes.Structure):
    _fields_ = [("psnr", c_double), ("ssim", c_double), ("mae", c_double), ("sam", c_double)]


PIXEL_U16 = 1
PIXEL_F32 = 2
PRECISION_FP32 = 0
PRECISION_BF16 = 1

try:
    lib = ctypes.CDLL(LIBRARY_PATH)
except OSError as e:  # a package copied without its library, or a system library missing
    raise ImportError(f"lumosaic: cannot load the C library {LIBRARY_PATH}: {e}") from e

_E = POINTER(_Error)
_VP = c_void_p
_SIGNATURES = {
    "lm_api_status_str": (c_char_p, [c_int]),
    "lm_api_version": (c_char_p, [POINTER(c_int), POINTER(c_int), POINTER(c_int)]),
    "lm_api_system_load": (c_int, [c_char_p, POINTER(_VP), _E]),
    "lm_api_system_free": (None, [_VP]),
    "lm_api_system_info": (c_int, [_VP, POINTER(c_int), POINTER(c_int), POINTER(c_int), _E]),
    "lm_api_cube_read": (c_int, [c_char_p, c_char_p, POINTER(_VP), _E]),
    "lm_api_cube_write": (c_int, [c_char_p, _VP, _E]),
    "lm_api_cube_create": (c_int, [c_int, c_int, c_int, POINTER(c_float), POINTER(_VP), _E]),
    "lm_api_cube_free": (None, [_VP]),
    "lm_api_cube_shape": (c_int, [_VP, POINTER(c_int), POINTER(c_int), POINTER(c_int), _E]),
    "lm_api_cube_data": (c_void_p, [_VP]),
    "lm_api_cube_wavelengths": (c_void_p, [_VP]),
    "lm_api_cube_srgb": (c_int, [_VP, c_float, _VP, c_size_t, _E]),
    "lm_api_simulate": (c_int, [_VP, _VP, POINTER(NoiseStruct), c_uint64, c_int, _VP, _VP,
                                c_size_t, _E]),
    "lm_api_model_load": (c_int, [c_char_p, _VP, POINTER(_VP), _E]),
    "lm_api_model_load_bundled": (c_int, [c_int, _VP, POINTER(_VP), _E]),
    "lm_api_model_load_auto": (c_int, [c_char_p, c_double, _VP, POINTER(_VP), _E]),
    "lm_api_model_free": (None, [_VP]),
    "lm_api_model_average": (c_int, [POINTER(c_char_p), c_int, c_char_p, _E]),
    "lm_api_model_convert": (c_int, [c_char_p, c_char_p, c_int, _E]),
    "lm_api_model_info": (c_int, [_VP, POINTER(c_char_p), POINTER(c_int), POINTER(c_int),
                                  POINTER(c_int), _E]),
    "lm_api_model_set_threads": (c_int, [_VP, c_int, _E]),
    "lm_api_model_set_noise_level": (c_int, [_VP, c_double, _E]),
    "lm_api_model_set_patchwise": (c_int, [_VP, c_int, _E]),
    "lm_api_model_set_precision": (c_int, [_VP, c_int, _E]),
    "lm_api_model_set_clamp": (c_int, [_VP, c_int, _E]),
    "lm_api_reconstruct": (c_int, [_VP, POINTER(Frame), _VP, c_size_t, _VP, _E]),
    "lm_api_reconstruct_sequence": (c_int, [_VP, POINTER(Frame), c_int, c_int, _VP, c_size_t,
                                            _VP, _E]),
    "lm_api_metrics_compute": (c_int, [_VP, _VP, c_int, c_int, c_int, POINTER(MetricsStruct),
                                       _E]),
}
for _name, (_res, _args) in _SIGNATURES.items():
    _fn = getattr(lib, _name)
    _fn.restype = _res
    _fn.argtypes = _args


def call(name: str, *args) -> None:
    """Call lm_api_<name>(*args, &err); raise :class:`Error` with its message on failure."""
    err = _Error()
    status = getattr(lib, "lm_api_" + name)(*args, ctypes.byref(err))
    if status != 0:
        msg = err.message.decode("utf-8", "replace") or lib.lm_api_status_str(status).decode()
        raise Error(status, msg)


def version() -> str:
    """The library's API version, "MAJOR.MINOR.PATCH"."""
    return lib.lm_api_version(None, None, None).decode()
