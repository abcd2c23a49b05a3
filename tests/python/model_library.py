"""The generated library's C structures as ctypes sees them (runtime/include/chaincomp/model_info.hpp,
model_library.hpp), for the tests that call a built model directly."""

import ctypes

VOID_P, DBL_P = ctypes.c_void_p, ctypes.POINTER(ctypes.c_double)


class Entry(ctypes.Structure):
    """runtime/include/chaincomp/model_info.hpp: ModelEntry."""
    _fields_ = [("info", VOID_P), ("model_size", ctypes.c_size_t), ("model_align", ctypes.c_size_t),
                ("prepare", ctypes.CFUNCTYPE(None, DBL_P, VOID_P)),
                ("pose_exact", ctypes.CFUNCTYPE(None, VOID_P, DBL_P, DBL_P)),
                ("pose_nominal", ctypes.CFUNCTYPE(None, VOID_P, DBL_P, DBL_P)),
                ("pose_jacobian", ctypes.CFUNCTYPE(None, VOID_P, DBL_P, DBL_P, DBL_P)),
                ("error", ctypes.CFUNCTYPE(ctypes.c_bool, VOID_P, DBL_P, ctypes.c_int, DBL_P)),
                ("max_order", ctypes.c_int),
                ("compensate", VOID_P), ("workspace_size", ctypes.c_size_t), ("workspace_align", ctypes.c_size_t),
                ("init_workspace", VOID_P), ("num_errors", ctypes.c_int), ("attach_varying", VOID_P),
                ("pose_jacobian_gain", ctypes.CFUNCTYPE(None, VOID_P, DBL_P, DBL_P, DBL_P, DBL_P))]


class Library(ctypes.Structure):
    _fields_ = [("abi", ctypes.c_int), ("layout", ctypes.c_uint32 * 6), ("name", ctypes.c_char_p),
                ("source_hash", ctypes.c_uint64), ("source_text", VOID_P), ("source_size", ctypes.c_size_t),
                ("toolchain", ctypes.c_char_p), ("entry", ctypes.POINTER(Entry))]


def arr(values):
    return (ctypes.c_double * len(values))(*values)
