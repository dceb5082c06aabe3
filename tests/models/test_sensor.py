"""The pressure sensor the likelihoods assume is the stand's (``StandDescription.pressure_sensor_*``,
``--stand FILE.toml``): its resolution is the measured-pressure models' holding sd, its gain error
the prior of a test's common offset, and the virtual stand records with the same sensor."""

from __future__ import annotations

import numpy as np
import pytest

from uq._data.stand_description import PAPER_STAND, read_stand
from uq._inference.latent import common_offset
from uq._models.pair import holding_sd_Pa
from uq._stand.shapes import sensor_gain

COARSE = PAPER_STAND.replace(pressure_sensor_gain_sd=0.01, pressure_sensor_resolution_pa=10.0)


def test_the_models_take_the_stands_sensor():
    assert holding_sd_Pa(5.0, PAPER_STAND, measured=True, shape=(2,)) == pytest.approx(
        [1.0 / np.sqrt(12.0)] * 2
    )
    assert holding_sd_Pa(5.0, COARSE, measured=True, shape=(2,)) == pytest.approx(
        [10.0 / np.sqrt(12.0)] * 2
    )
    dp = np.random.default_rng(4).normal(0.0, 300.0, 40)
    _, sd_paper = common_offset(dp, 5e5, stand=PAPER_STAND)
    _, sd_coarse = common_offset(dp, 5e5, stand=COARSE)
    assert sd_coarse > sd_paper  # a less accurate sensor leaves more of the offset unknown


def test_the_virtual_stand_records_with_the_same_sensor(tmp_path):
    assert sensor_gain(7, COARSE) == pytest.approx(10.0 * sensor_gain(7))  # same stream, 10x sd
    f = tmp_path / "stand.toml"
    f.write_text("pressure_sensor_gain_sd = 0.002\npressure_sensor_resolution_pa = 5.0\n")
    stand = read_stand(f)
    assert stand.pressure_sensor_gain_sd == 0.002 and stand.pressure_sensor_resolution_pa == 5.0
    assert "pressure_sensor_gain_sd=0.002" in repr(stand)
