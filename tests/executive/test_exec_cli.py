"""``lrauv exec`` and ``lrauv log recover`` as a user runs them: real processes, files and sockets."""

from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path

import pytest

from executive.recorder import LogError, read_messages
from tests.support import REPO
from tests.support.helpers import start_west_of_goal, wait_until
from tests.support.loop_rig import LRAUV, Sim


def _lrauv(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*LRAUV, *args], capture_output=True, text=True, timeout=60, cwd=REPO)


@pytest.fixture()
def table_path(demo_plan, tmp_path) -> Path:
    path = tmp_path / "demo.lrpt"
    demo_plan.table.save(path)
    return path


def _one_line_error(proc: subprocess.CompletedProcess[str], *needles: str) -> None:
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr
    err = proc.stderr.strip()
    assert err.startswith("lrauv: error:") and len(err.splitlines()) == 1, err
    for needle in needles:
        assert needle in err, err


def test_exec_refuses_a_missing_or_corrupt_table(table_path, tmp_path):
    _one_line_error(_lrauv("exec", "--table", str(tmp_path / "none.lrpt")), "none.lrpt")
    broken = tmp_path / "broken.lrpt"
    data = bytearray(table_path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    broken.write_bytes(bytes(data))
    _one_line_error(_lrauv("exec", "--table", str(broken), "--log", str(tmp_path / "x.mcap")), "broken.lrpt")
    assert not (tmp_path / "x.mcap").exists()


def test_exec_refuses_a_mission_whose_goal_is_not_the_tables(table_path, tmp_path):
    text = (REPO / "missions" / "demo.yaml").read_text().replace("lat_deg: 33.40", "lat_deg: 33.45")
    other = tmp_path / "other.yaml"
    other.write_text(text)
    _one_line_error(_lrauv("exec", "--table", str(table_path), "--mission", str(other)), "other.yaml", "goal")


@pytest.mark.parametrize(("flag", "value"), [("--telemetry-hz", "0"), ("--max-wall-s", "-1"), ("--linger-s", "nan")])
def test_exec_refuses_bad_numbers(table_path, flag, value):
    _one_line_error(_lrauv("exec", "--table", str(table_path), flag, value), flag)


@pytest.mark.slow
def test_a_killed_executive_leaves_a_log_that_log_recover_repairs(demo_plan, table_path, synthetic_forecast, tmp_path):
    """kill -9 the executive mid-mission; `lrauv log recover` gives back everything flushed before the kill."""
    lon, lat = start_west_of_goal(demo_plan.table, cells=6)
    sim = Sim(synthetic_forecast, (lon, lat), "--position-delay-s", "5", "--heartbeat-timeout-s", "600")
    log = tmp_path / "killed.mcap"
    ex = subprocess.Popen([*LRAUV, "exec", "--table", str(table_path), "--link", f"udpout:127.0.0.1:{sim.port}",
                           "--log", str(log), "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert wait_until(lambda: log.exists() and log.stat().st_size > 200_000, 60), "the executive wrote no log"
        time.sleep(0.3)
        ex.send_signal(signal.SIGKILL)
        ex.wait(10)
    finally:
        if ex.poll() is None:
            ex.kill()
            ex.wait()
        sim.stop()
    assert ex.returncode == -signal.SIGKILL
    with pytest.raises(LogError, match="lrauv log recover"):
        list(read_messages(log))
    proc = _lrauv("log", "recover", str(log))
    assert proc.returncode == 0, proc.stderr
    assert "truncated at byte" in proc.stdout
    recovered = tmp_path / "killed.recovered.mcap"
    decisions = [p for _, _, p in read_messages(recovered, ["/executive/decision"])]
    assert len(decisions) > 100
    assert [d["time_s"] for d in decisions] == sorted(d["time_s"] for d in decisions)
    assert {d["action"] for d in decisions} & {"FORWARD", "DRIFT", "ROTATE_LEFT", "ROTATE_RIGHT", "UP", "DOWN"}
    policy = [p for _, _, p in read_messages(recovered, ["/executive/policy"])]
    assert policy and policy[0]["table_crc32"] == f"{demo_plan.table.crc32:08x}"
