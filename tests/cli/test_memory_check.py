"""The up-front memory check: a campaign whose predicted peak exceeds the available memory is
refused in one line before any fitting (exit 2); the available memory is patched, nothing large
is allocated."""

from __future__ import annotations

import pytest
from cli_helpers import one_line, run

import uq._io.memory as memory
from uq._io.errors import InputError
from uq._io.memory import GB, MemoryModel, available_bytes, check_fits_in_memory

CAMPAIGN = "data/n50/recordings.csv"  # 407 readings


@pytest.fixture
def no_fitting(monkeypatch):
    import uq._models.cubic_fit

    def forbidden(*a, **k):
        raise AssertionError("a fit started before the memory check")

    monkeypatch.setattr(uq._models.cubic_fit, "fit_campaign", forbidden)


@pytest.fixture
def machine(monkeypatch):
    """A machine with the given MemAvailable (GB), no cgroup limit, no UQ_MEMORY_GB, nothing held."""

    def set_available(gb):
        monkeypatch.delenv(memory.ENV, raising=False)
        monkeypatch.setattr(memory, "_meminfo_available", lambda: gb * GB)
        monkeypatch.setattr(memory, "_cgroup_room", lambda: None)
        monkeypatch.setattr(memory, "_held_bytes", lambda: 0.0)

    return set_available


@pytest.mark.parametrize("command", ["fit", "report"])
def test_a_campaign_too_large_is_refused_in_one_line_before_fitting(
    command, machine, no_fitting, capsys, tmp_path
):
    need = memory.FIT.peak_bytes(407) / GB
    machine(need - 0.05)  # just short of what the 407 readings need
    argv = [command, CAMPAIGN] + (["--out", tmp_path / "r"] if command == "report" else [])
    assert run(argv) == 2
    out, err = capsys.readouterr()
    line = one_line(err)
    assert out == "" and "Traceback" not in err
    for words in (CAMPAIGN, "407 readings", f"{need:.1f} GB", f"uq {command}", memory.ENV):
        assert words in line, (words, line)
    assert not (tmp_path / "r").exists()


def test_fit_out_is_checked_with_one_test_held_at_a_time(machine, no_fitting, capsys, tmp_path):
    """uq fit --out holds one test's InferenceData at a time: a machine with room for the fit but
    not for that is refused for --out only (data/n50: 11 tests of 37 readings)."""
    fit, out = memory.FIT.peak_bytes(407) / GB, memory.FIT_OUT.peak_bytes(407, 37) / GB
    assert out > fit
    machine((fit + out) / 2)
    assert run(["fit", CAMPAIGN, "--out", tmp_path / "o"]) == 2
    line = one_line(capsys.readouterr().err)
    assert "uq fit --out" in line and "largest test" in line and f"{out:.1f} GB" in line
    assert not (tmp_path / "o").exists()
    assert run(["fit", CAMPAIGN]) != 2  # without --out it gets to the fit
    assert "a fit started before the memory check" in capsys.readouterr().err


def test_the_override_lets_the_campaign_through(machine, no_fitting, monkeypatch, capsys):
    machine(0.01)
    for value in ("off", "64"):
        monkeypatch.setenv(memory.ENV, value)
        assert run(["fit", CAMPAIGN]) != 2  # it got to the fit (which the fixture stops)
        assert "a fit started before the memory check" in capsys.readouterr().err


@pytest.mark.parametrize("value", ["lots", "-3", "0"])
def test_a_bad_override_is_one_line(value, monkeypatch, no_fitting, capsys):
    monkeypatch.setenv(memory.ENV, value)
    assert run(["fit", CAMPAIGN]) == 2
    assert memory.ENV in one_line(capsys.readouterr().err)


def test_the_model_and_the_largest_campaign(monkeypatch):
    monkeypatch.setattr(memory, "_held_bytes", lambda: 0.0)
    m = MemoryModel(constant_bytes=0.5 * GB, bytes_per_reading=50e3)
    assert m.peak_bytes(200_000) == pytest.approx(10.5 * GB)
    assert m.largest(10.5 * GB) == 200_000
    assert m.peak_bytes(m.largest(3.3 * GB)) <= 3.3 * GB < m.peak_bytes(m.largest(3.3 * GB) + 1)
    assert m.largest(0.1 * GB) == 0
    held = m._replace(bytes_per_test_reading=100e3)  # one test of ten held at a time
    assert held.peak_bytes(200_000, 20_000) == pytest.approx(12.5 * GB)
    assert held.largest(12.5 * GB, 0.1) == 200_000
    check_fits_in_memory("f.csv", 200_000, "uq fit", m, available=10.5 * GB)  # exactly fits
    with pytest.raises(InputError, match=r"f\.csv: 200001 readings need about 10\.5 GB"):
        check_fits_in_memory("f.csv", 200_001, "uq fit", m, available=10.5 * GB)


def test_available_memory_from_meminfo_and_cgroup(tmp_path, monkeypatch):
    meminfo = tmp_path / "meminfo"
    meminfo.write_text("MemTotal:       24000000 kB\nMemFree: 1 kB\nMemAvailable:   2000000 kB\n")
    assert memory._meminfo_available(str(meminfo)) == 2000000 * 1024
    assert memory._meminfo_available(str(tmp_path / "none")) is None
    (tmp_path / "memory.max").write_text("max\n")
    assert memory._cgroup_room(str(tmp_path)) is None  # no limit
    (tmp_path / "memory.max").write_text("3000000000\n")
    (tmp_path / "memory.current").write_text("1000000000\n")
    assert memory._cgroup_room(str(tmp_path)) == 2e9
    monkeypatch.delenv(memory.ENV, raising=False)
    monkeypatch.setattr(memory, "_meminfo_available", lambda: 5e9)
    monkeypatch.setattr(memory, "_cgroup_room", lambda: 2e9)
    assert available_bytes() == 2e9  # the tighter of the two
    monkeypatch.setattr(memory, "_cgroup_room", lambda: None)
    monkeypatch.setattr(memory, "_meminfo_available", lambda: None)
    assert available_bytes() is None  # unknown: nothing is checked
    check_fits_in_memory("f.csv", 10**9, "uq fit")
