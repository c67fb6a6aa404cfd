"""Environment variables acq sets for itself and its workers, kept apart from the user's: commands acq runs for the
user (``--on-alarm``) get the environment the user started acq with."""

from __future__ import annotations

import os

#: Environment variables acq set itself (:func:`set_default_env`) and their values: not passed to commands run for
#: the user.
_SET_BY_ACQ: dict[str, str] = {}


def set_default_env(name: str, value: str) -> None:
    """Set environment variable ``name`` to ``value`` unless the user set it; remember that acq did."""
    if name not in os.environ:
        os.environ[name] = _SET_BY_ACQ[name] = value


def user_environment() -> dict[str, str]:
    """The environment without the variables acq set (:func:`set_default_env`, still at acq's value): for commands
    acq runs for the user (``--on-alarm``), which must see the user's settings, not acq's BLAS threads."""
    return {name: value for name, value in os.environ.items() if _SET_BY_ACQ.get(name) != value}


#: The variables that set the BLAS libraries' thread count (OpenBLAS, OpenMP, MKL).
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def pin_blas_threads(threads: str = "1") -> None:
    """Start BLAS with ``threads`` threads in this process and those it starts, unless the user chose (before numpy
    loads its BLAS: the count is read then)."""
    for name in BLAS_THREAD_VARIABLES:
        set_default_env(name, threads)
