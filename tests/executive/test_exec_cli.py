"""``lrauv exec`` and ``lrauv log recover`` as a user runs them: real processes, files and sockets."""

from __future__ import annotations

import signal
import socket
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
    assert "truncated at byte" in " ".join(proc.stdout.split())
    recovered = tmp_path / "killed.recovered.mcap"
    decisions = [p for _, _, p in read_messages(recovered, ["/executive/decision"])]
    assert len(decisions) > 100
    assert [d["time_s"] for d in decisions] == sorted(d["time_s"] for d in decisions)
    assert {d["action"] for d in decisions} & {"FORWARD", "DRIFT", "ROTATE_LEFT", "ROTATE_RIGHT", "UP", "DOWN"}
    policy = [p for _, _, p in read_messages(recovered, ["/executive/policy"])]
    assert policy and policy[0]["table_crc32"] == f"{demo_plan.table.crc32:08x}"


def _killed_run(demo_plan, tmp_path: Path, log: Path) -> Path:  # type: ignore[no-untyped-def]
    """A state directory as a killed executive left it, naming ``log``; returns the directory."""
    from executive import durable, goal_tables

    state = tmp_path / "state"
    durable.save(state, goal_tables.single(demo_plan.table, on_arrival="hold"), {}, log_path=log, mission_path=None)
    return state


def _resume(state: Path, new_log: Path) -> subprocess.CompletedProcess[str]:
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # an autopilot that says nothing
    silent.bind(("127.0.0.1", 0))
    try:
        return _lrauv("exec", "--resume", str(state), "--log", str(new_log), "--max-wall-s", "0.3",
                      "--link", f"udpout:127.0.0.1:{silent.getsockname()[1]}")
    finally:
        silent.close()


def test_resume_recovers_the_killed_log_where_log_points_not_on_the_old_disk(demo_plan, tmp_path):
    from executive.recorder import Recorder, Topic

    old_disk = tmp_path / "full-disk"
    old_disk.mkdir()
    killed = old_disk / "run.mcap"
    with Recorder(killed, chunk_size=512) as rec:
        for i in range(40):
            rec.write(Topic.STATE, float(i), {"time_s": float(i)})
    killed.write_bytes(killed.read_bytes()[:-300])  # no footer: the process was killed
    before = sorted(p.name for p in old_disk.iterdir())
    new_log = tmp_path / "elsewhere" / "resumed.mcap"
    proc = _resume(_killed_run(demo_plan, tmp_path, killed), new_log)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert sorted(p.name for p in old_disk.iterdir()) == before  # nothing written on the killed run's disk
    recovered = tmp_path / "elsewhere" / "run.recovered.mcap"
    assert f"recovered into {recovered}" in " ".join(proc.stdout.split())  # lines over 100 columns wrap
    assert 0 < len(list(read_messages(recovered))) <= 40  # up to its last complete record
    assert list(read_messages(new_log))  # the resumed run's own log, finished


def test_resume_starts_even_when_the_killed_log_cannot_be_recovered(demo_plan, tmp_path):
    unreadable = tmp_path / "run.mcap"
    unreadable.mkdir()  # EISDIR on open: as unreadable as a log on a failed disk
    new_log = tmp_path / "resumed.mcap"
    proc = _resume(_killed_run(demo_plan, tmp_path, unreadable), new_log)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    words = " ".join(proc.stdout.split())  # lines over 100 columns wrap under their value
    assert f"{unreadable}: not recovered" in words and "lrauv log recover" in words
    assert list(read_messages(new_log))


@pytest.mark.parametrize(("flag", "value"), [("--upload-max-files", "0"), ("--upload-max-mb", "nan")])
def test_exec_refuses_a_bad_upload_quota(table_path, flag, value):
    _one_line_error(_lrauv("exec", "--table", str(table_path), flag, value), flag)
