"""
Holding the OpenBLAS libraries to one thread around small, many-call numerics.

Part of :mod:`imu_allan.core.allan`.
"""

from contextlib import contextmanager
import ctypes
import threading


def _openblas_thread_apis() -> list:
    """
    Return (get, set) of every OpenBLAS loaded in the process (numpy's, scipy's).

    numpy and scipy wheels each bundle their own OpenBLAS; scipy's (L-BFGS-B, LAPACK)
    is loaded only when a scipy module needs it, so the list is read again each time
    (the libraries already opened are remembered).
    """
    try:
        with open('/proc/self/maps', encoding='ascii', errors='replace') as f:
            paths = {ln.split()[-1] for ln in f if 'openblas' in ln.lower()}
    except OSError:
        return []
    for path in sorted(paths - set(_BLAS_LIBS)):
        _BLAS_LIBS[path] = None
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for suffix in ('64_', '_64_', ''):
            for prefix in ('scipy_openblas', 'openblas'):
                get = getattr(lib, f'{prefix}_get_num_threads{suffix}', None)
                put = getattr(lib, f'{prefix}_set_num_threads{suffix}', None)
                if get is not None and put is not None and _BLAS_LIBS[path] is None:
                    get.restype = ctypes.c_int
                    put.argtypes = [ctypes.c_int]
                    _BLAS_LIBS[path] = (get, put)
    return [api for api in _BLAS_LIBS.values() if api is not None]


_BLAS_LOCK = threading.Lock()

_BLAS_LIBS: dict = {}

_BLAS_STATE: dict = {'depth': 0, 'saved': []}


@contextmanager
def single_thread_blas():
    """
    Hold the OpenBLAS libraries to one thread (what threadpoolctl does; else a no-op).

    The kernels call dot on many cache-sized tiles, and already run one thread per
    axis; the fits work on matrices of a few tens of rows.  OpenBLAS's own threads
    would only oversubscribe the cores (measured: twice the CPU time of a search).
    """
    with _BLAS_LOCK:
        st = _BLAS_STATE
        if st['depth'] == 0:
            st['saved'] = [(api, api[0]()) for api in _openblas_thread_apis()]
            for api, _ in st['saved']:
                api[1](1)
        st['depth'] += 1
    try:
        yield
    finally:
        with _BLAS_LOCK:
            st['depth'] -= 1
            if st['depth'] == 0:
                for api, n in st['saved']:
                    if n:
                        api[1](n)
