"""A test's stand-in for a fitted model: the :class:`uq._models.fitted.FittedModel` members a
hand-written model of known draws (a cylinder, the stand's own spring) needs besides its
``force_draws`` and ``volume_area_draws``, so that design and margins take it as they take a fit."""

from __future__ import annotations

from uq._models.fitted import refuse_extrapolation


class ModelDouble:
    """Mix into a class with ``label``, ``height_range_m``, ``pressure_range_bar`` and the draws."""

    has_volume = True
    has_dvdp = False
    omitted_reason = None
    dvdp_words = "the model's own"

    def on_draws(self, n: int):
        return self

    def check_range(self, height_m, p_bar, param=None) -> None:
        refuse_extrapolation(
            height_m, p_bar, self.height_range_m, self.pressure_range_bar, param, self.label
        )


class ForceOnlyDouble(ModelDouble):
    """A model without a volume (a force-only campaign's)."""

    has_volume = False
    omitted_reason = "volume results omitted: force-only campaign (no piston_* or volume_* column)"
