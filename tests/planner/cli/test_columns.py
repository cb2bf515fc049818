"""Every line the commands print fits in 100 columns, and nothing is lost doing so.

Through ``planner.cli.main`` as a user types it, on the demo mission and a short real dive; the evaluation's
two tables are held to the same width in tests/planner/shore/test_evaluate.py, batch and holdout in
tests/planner/test_scale_out.py.
"""

from __future__ import annotations

import pytest

from planner.cli import main
from planner.contract.columns import WIDTH, fit
from tests.support.helpers import DEMO_MISSION


def wide_lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if len(line) > WIDTH]


def words(text: str) -> list[str]:
    return text.split()


def test_a_labelled_line_wraps_under_its_value_and_keeps_every_word():
    line = "forecast   " + " ".join(f"word{n}" for n in range(40))
    text = fit(line)
    assert wide_lines(text) == [] and words(text) == words(line)
    assert all(row.startswith(" " * 11) and row[11] != " " for row in text.splitlines()[1:])
    assert fit("source:     " + "x " * 60).splitlines()[1].startswith(" " * 12 + "x")  # the value's own column
    path = "/" + "deep/" * 30 + "f.nc"
    assert fit(f"wrote      {path} and more").splitlines() == [f"wrote      {path}", " " * 11 + "and more"]  # never cut
    assert fit("short\n\n  table row") == "short\n\n  table row"


def test_plan_summary_fits_in_100_columns(synthetic_forecast, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["plan", str(DEMO_MISSION), f"--forecast={synthetic_forecast}", "--out=d.lrpt",
                 "--start=-117.96,33.34,0,0", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert wide_lines(out) == [], out
    joined = " ".join(words(out))
    assert f"forecast {synthetic_forecast} [sha256:" in joined and "step 0 (2026-01-15T00:00:00Z)" in joined, out
    assert "start (-117.96, 33.34, 0 m, 0 deg), state (l, j, i, k) =" in joined, out


def test_forecast_info_fits_in_100_columns(synthetic_forecast, capsys):
    assert main(["forecast", "info", str(synthetic_forecast)]) == 0
    out = capsys.readouterr().out
    assert wide_lines(out) == [] and "lon:" in out, out


@pytest.mark.slow
def test_replay_summary_fits_in_100_columns(dive_log, capsys):
    assert main(["replay", str(dive_log), "--no-audit", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert wide_lines(out) == [], out
    assert "deviation  largest from the nominal path" in out and "(lon, lat " in " ".join(words(out)), out
