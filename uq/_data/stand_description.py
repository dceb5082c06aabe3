"""What a test stand is: the constants that the virtual stand uses to make noise and that the
models use for their noise formulas and priors. One home, so that a different stand is one
description (``--stand FILE.toml``) rather than constants edited in several modules.

The default, ``PAPER_STAND``, is the stand of the paper's section 3.2 with this project's
stated assumptions where the paper is silent (gas volume; each figure read as one standard
deviation). A TOML file overrides any subset of the fields, in the units of the field names::

    # my_stand.toml
    load_cell_rel_sd = 0.003          # 0.3 % of the force
    pressure_holding_bar = 0.02       # held within 0.02 bar from 1 bar up
    receiver_air_m3 = 0.0035          # receiver and pipes

Unknown keys, wrong types and non-positive values are refused with one line naming the file
and the key.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from uq._io.errors import InputError


@dataclass(frozen=True)
class StandDescription:
    """Error budget and gas volumes of a stand, SI units except where a field says bar.

        load_cell_rel_sd            relative sd of the force reading (0.5 % in the paper)
        pressure_holding_bar        sd of the held overpressure from 1 bar up (0.01 bar)
        pressure_holding_floor_bar  sd at the lowest pressures (0.001 bar at 0.1 bar); between the
                                    floor and 1 bar the sd is proportional to p_u
        displacement_sd_m           sd of the true height about the commanded one (0.02 mm)
        caliper_sd_m                sd of the piston reading (0.01 mm)
        receiver_air_m3             air outside the element: receiver, pipes, cylinder (assumed 2 L)
        element_volume_at_xmax_m3   element's own air volume at the highest height (assumed 4.2 L)
        p_atm_bar                   atmospheric pressure
        error_df                    0: every reading error is Gaussian (the models' assumption);
                                    > 2: Student t with that many degrees of freedom, scaled to the
                                    same sd (a stand with occasional larger disturbances)
        pressure_error_corr         0: the pressure-holding errors of successive readings are
                                    independent (the models' assumption); in (0, 1): their lag-one
                                    correlation in recording order (AR(1), same sd), as a slow
                                    pressure controller leaves them
        pressure_sensor_gain_sd     the pressure sensor's relative accuracy, read as a gain error
                                    common to a test (0.1 %, the paper's sensor, section 3.2)
        pressure_sensor_resolution_pa  its resolution, Pa (1 Pa assumed: the paper's sensor
                                    resolves far below the holding error)

    The sensor matters only for recordings with measured pressures (a ``set_pressure_*`` column):
    the models correct each reading by its measured deviation, whose common offset the gain error
    leaves unknown (uq._inference.latent.common_offset) and whose rounding is the resolution.

    The last two describe stands whose noise differs in *form* from what every model's likelihood
    assumes (independent Gaussian errors): the stand uses them, the models ignore them, so the
    tests can check the models' intervals against noise that the models do not share.

        ``PAPER_STAND`` is the default; :meth:`replace` or :func:`read_stand` give another stand, which
        ``uq.simulate(..., stand=)`` makes noise with and ``uq.fit_surface``/``uq.diagnose`` model:

        >>> import uq
        >>> uq.PAPER_STAND.load_cell_rel_sd, uq.PAPER_STAND.gas_volume_at_xmax_m3
        (0.005, 0.0062)
        >>> float(uq.PAPER_STAND.replace(pressure_holding_bar=0.02).pressure_sd_bar(5.0))
        0.02
    """

    load_cell_rel_sd: float = 0.005
    pressure_holding_bar: float = 0.01
    pressure_holding_floor_bar: float = 0.001
    displacement_sd_m: float = 0.02e-3
    caliper_sd_m: float = 0.01e-3
    receiver_air_m3: float = 2.0e-3
    element_volume_at_xmax_m3: float = 4.2e-3
    p_atm_bar: float = 1.01325
    error_df: float = 0.0
    pressure_error_corr: float = 0.0
    pressure_sensor_gain_sd: float = 0.001
    pressure_sensor_resolution_pa: float = 1.0

    def __post_init__(self):
        if self.error_df != 0 and not self.error_df > 2:
            raise ValueError(
                f"error_df must be 0 (Gaussian) or above 2 (finite variance), got {self.error_df!r}"
            )
        if not 0 <= self.pressure_error_corr < 1:
            raise ValueError(
                f"pressure_error_corr must lie in 0 <= corr < 1, got {self.pressure_error_corr!r}"
            )

    @property
    def gas_volume_at_xmax_m3(self) -> float:
        """All the air the pressure holding acts on, m^3: the element's at the highest height and
        the receiver's. The same at every height (eq. 4: the gas/water boundary moves inside the
        receiver as the element is compressed)."""
        return self.receiver_air_m3 + self.element_volume_at_xmax_m3

    def pressure_sd_bar(self, pressure_bar):
        """sd of the pressure holding at overpressure p_u (bar): ``pressure_holding_bar`` from
        1 bar up, proportional to p_u below, never under ``pressure_holding_floor_bar``."""
        p = np.asarray(pressure_bar, float)
        return np.maximum(
            self.pressure_holding_bar * np.minimum(1.0, p), self.pressure_holding_floor_bar
        )

    def __repr__(self) -> str:
        changed = ", ".join(f"{k}={v:g}" for k, v in self.changes().items())
        return f"StandDescription(the paper's stand{' except ' + changed if changed else ''})"

    def replace(self, **changes) -> StandDescription:
        return dataclasses.replace(self, **changes)

    def changes(self) -> dict[str, float]:
        """The fields whose values differ from the paper's stand (empty for ``PAPER_STAND``)."""
        return {
            f.name: getattr(self, f.name)
            for f in dataclasses.fields(self)
            if getattr(self, f.name) != f.default
        }

    def noise_form_fields(self) -> list[str]:
        """The fields set here that make the noise differ in form from the models' independent
        Gaussian errors (``error_df``, ``pressure_error_corr``): the virtual stand uses them, the
        models cannot."""
        return [f for f in ("error_df", "pressure_error_corr") if getattr(self, f) != 0]


PAPER_STAND = StandDescription()

_ALLOW_ZERO = {
    "load_cell_rel_sd",
    "pressure_holding_bar",
    "pressure_holding_floor_bar",
    "displacement_sd_m",
    "caliper_sd_m",
    "receiver_air_m3",
    "error_df",
    "pressure_error_corr",
    "pressure_sensor_gain_sd",
}


def stand_or_paper(path: str | Path | None) -> StandDescription:
    """The stand described in ``path``, or the paper's stand when no file is given."""
    return read_stand(path) if path else PAPER_STAND


def read_stand(path: str | Path) -> StandDescription:
    """A stand description from a TOML file; fields not given keep the paper's values.

    >>> import pathlib, tempfile, uq
    >>> f = pathlib.Path(tempfile.mkdtemp()) / "my_stand.toml"
    >>> _ = f.write_text("load_cell_rel_sd = 0.003\\nreceiver_air_m3 = 0.0035\\n")
    >>> stand = uq.read_stand(f)
    >>> stand.load_cell_rel_sd, stand.pressure_holding_bar, stand == uq.PAPER_STAND
    (0.003, 0.01, False)
    >>> rec = uq.simulate("n50", seed=1, layout=uq.Layout(pressures_bar=(1.0, 5.0), step_m=0.01), stand=stand)
    >>> rec.comments[2]
    "Procedure of the paper's section 3.4, noise from its error budget (section 3.2) except load_cell_rel_sd = 0.003, receiver_air_m3 = 0.0035."
    """
    path = Path(path)
    try:
        with path.open("rb") as f:
            raw = tomllib.load(f)
    except FileNotFoundError:
        raise InputError(f"stand: {path}: no such file", param="stand") from None
    except IsADirectoryError:
        raise InputError(
            f"stand: {path} is a directory, expected a TOML file", param="stand"
        ) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not valid TOML ({exc})") from None
    fields = {f.name for f in dataclasses.fields(StandDescription)}
    values = {}
    for key, value in raw.items():
        if key not in fields:
            raise InputError(
                f"{path}: unknown key '{key}'; expected some of {', '.join(sorted(fields))}"
            )
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not math.isfinite(value)
        ):
            raise InputError(f"{path}: key '{key}' must be a finite number, got {value!r}")
        if value < 0 or (value == 0 and key not in _ALLOW_ZERO):
            raise InputError(
                f"{path}: key '{key}' must be {'non-negative' if key in _ALLOW_ZERO else 'positive'}, got {value!r}"
            )
        values[key] = float(value)
    try:
        return StandDescription(**values)
    except ValueError as exc:
        raise InputError(f"{path}: {exc}") from None
