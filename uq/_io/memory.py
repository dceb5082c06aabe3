"""Will a campaign fit in this machine's memory? The check every fitting command makes up front.

A command's peak resident memory is linear in the readings of its campaign: a constant (the
imports, JAX's compiled programs, the retained draws) plus a cost per reading (the readings'
share of every vmapped log posterior, exact draw and check). :data:`FIT` is that model for
``uq fit``, measured by ``benchmarks/bench.py --memory`` (which reports the fitted constant and
slope at three sizes and the model's error at each). Before any fitting, a campaign whose
predicted peak exceeds the memory the machine has available is refused in one line that names
the file, the number of readings and the memory it would need (:func:`check_fits_in_memory`),
instead of the out-of-memory killer ending the command minutes later with no message.

The available memory is the kernel's ``MemAvailable`` (``/proc/meminfo``), lowered to a cgroup's
limit where one applies (``/sys/fs/cgroup/memory.max``); where neither can be read (not Linux)
nothing is checked. ``UQ_MEMORY_GB`` overrides it: a number of GB to plan with, or ``off``.
"""

from __future__ import annotations

import os
from typing import NamedTuple

from uq._io.errors import InputError

try:
    import resource
except ImportError:  # not a Unix: what the process holds is not known
    resource = None

GB = 1e9
ENV = "UQ_MEMORY_GB"


class MemoryModel(NamedTuple):
    """Peak resident memory of a command: ``constant_bytes + bytes_per_reading * readings +
    bytes_per_test_reading * (readings of the largest test)``. The last term is for what is
    held one test at a time (``uq fit --out``: one test's InferenceData and NetCDF bytes)."""

    constant_bytes: float
    bytes_per_reading: float
    bytes_per_test_reading: float = 0.0

    def peak_bytes(self, readings: int, largest_test: int = 0) -> float:
        return (
            self.constant_bytes
            + self.bytes_per_reading * int(readings)
            + self.bytes_per_test_reading * int(largest_test)
        )

    def largest(self, available_bytes: float, test_share: float = 0.0) -> int:
        """The most readings whose predicted peak stays within ``available_bytes``, for campaigns
        whose largest test holds ``test_share`` of the readings (the same tests, finer steps)."""
        per = self.bytes_per_reading + self.bytes_per_test_reading * test_share
        return max(0, int((available_bytes - self.constant_bytes) // per))


#: ``uq fit`` (the default sampler settings: 4 ensembles of 32 walkers, at most 8000 retained
#: draws a test). ``benchmarks/bench.py --memory`` fits a line to uq fit's peak RSS on simulated
#: n50 campaigns of 11 tests at three steps (reports/bench/memory.json): a few kB a reading and
#: about 0.4 GB, with a constant that moves by about 0.25 GB between a run that compiles its
#: programs and one that finds them in the persistent compilation cache. The model rounds both up
#: (twice the steepest slope seen between measured sizes, the compiling run's constant and more),
#: since it is used beyond the largest measured campaign.
FIT = MemoryModel(constant_bytes=0.8 * GB, bytes_per_reading=20e3)
#: ``uq fit --out`` (and a ``uq batch`` fit): ``FIT``, the imports of ArviZ and xarray, and each
#: test's InferenceData in turn: its pointwise log-likelihoods and replicates of the force and
#: the piston (four float64 values a retained draw and reading: 256 kB a reading at 8000 draws)
#: and the NetCDF bytes made from them in memory (about twice as much again, compressed noise
#: and a copy); ``benchmarks/bench.py --memory`` measures it at its first step.
FIT_OUT = MemoryModel(constant_bytes=1.0 * GB, bytes_per_reading=20e3, bytes_per_test_reading=800e3)


def _meminfo_available(path: str = "/proc/meminfo") -> float | None:
    try:
        with open(path) as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0  # kB
    except OSError:
        return None
    return None


def _cgroup_room(root: str = "/sys/fs/cgroup") -> float | None:
    """What a cgroup v2 memory limit leaves (memory.max - memory.current), None without one."""
    try:
        with open(os.path.join(root, "memory.max")) as f:
            limit = f.read().strip()
        if limit == "max":
            return None
        with open(os.path.join(root, "memory.current")) as f:
            used = float(f.read().strip())
    except (OSError, ValueError):
        return None
    return max(float(limit) - used, 0.0)


def _held_bytes() -> float:
    """The resident memory this process has held so far (its imports): 0 where unknown."""
    if resource is None:
        return 0.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024.0  # kB on Linux


def available_bytes() -> float | None:
    """The memory a command may still take: ``UQ_MEMORY_GB`` when set (None for ``off``), else
    MemAvailable lowered to the cgroup's room; None where neither is known."""
    given = os.environ.get(ENV, "").strip()
    if given:
        if given.lower() == "off":
            return None
        try:
            value = float(given)
        except ValueError:
            raise InputError(
                f"{ENV}={given!r}: expected the memory to plan with in GB (e.g. 64) or off"
            ) from None
        if not value > 0:
            raise InputError(f"{ENV}={given!r}: expected a positive number of GB or off")
        return value * GB
    known = [a for a in (_meminfo_available(), _cgroup_room()) if a is not None]
    return min(known) if known else None


def check_fits_in_memory(
    path,
    readings: int,
    command: str,
    model: MemoryModel = FIT,
    available: float | None = None,
    largest_test: int = 0,
) -> None:
    """Raise :class:`InputError` (one line: the file, its readings, the memory they need, what is
    available, how to go on) when ``model``'s predicted peak for ``readings`` (``largest_test`` of
    them in the largest test) exceeds the available memory (``available``, default
    :func:`available_bytes`; nothing is checked when that is unknown or ``UQ_MEMORY_GB=off``)."""
    room = available_bytes() if available is None else available
    if room is None:
        return
    need = model.peak_bytes(readings, largest_test)
    if need - _held_bytes() <= room:  # what the process holds already is part of the peak
        return
    cost = f"{model.bytes_per_reading / 1e3:.0f} kB a reading"
    if model.bytes_per_test_reading:
        cost += f", {model.bytes_per_test_reading / 1e3:.0f} kB a reading of the largest test"
    share = largest_test / readings if readings else 0.0
    raise InputError(
        f"{path}: {readings} readings need about {need / GB:.1f} GB of memory for {command} "
        f"({cost} + {model.constant_bytes / GB:.1f} GB), {room / GB:.1f} GB are available (at "
        f"most about {model.largest(room, share)} readings): fit fewer readings (a coarser height "
        f"step), or set {ENV} to the GB to plan with (off: no check)"
    )
