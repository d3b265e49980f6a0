"""kincal fleet's engine: a run interrupted by Ctrl-C keeps the units finished by then, each
complete, and no partial one, writes no fleet prior or summary, and leaves no process; the
same fleet through a running Dask scheduler (--scheduler) gives the local cluster's
results; units are batched into tasks without losing any."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
import warnings

import numpy as np
import pytest

from kincal.cli import main
from kincal.errors import KincalWarning
from kincal.fleet.simulated import FleetModel
from kincal.identification.prior import FleetPrior
from kincal.robot import Robot

distributed = pytest.importorskip(
    "distributed", reason='kincal fleet needs Dask distributed: pip install "kincal[fleet]"')

N_UNITS = 16


@pytest.fixture(scope="module")
def units(tmp_path_factory):
    """N_UNITS tracker units u01..u16 (30 poses each)."""
    fm = FleetModel.of(Robot.load("ec66", tip="flange"), 3)
    return fm.tracker_files(tmp_path_factory.mktemp("units"), N_UNITS,
                            np.random.default_rng(4), n=30)


def _fleet_argv(files, out, *extra):
    return ["fleet", "ec66", *files, "--tip", "flange", "--tool-offset", "0", "0", "0.045",
            "--out-dir", str(out), *extra]


def _gone(pgid: int, timeout: float) -> bool:
    """True once no process of the group is left (the workers too)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.1)
    return False


def _default_sigint():
    """The command as a terminal starts it: a test run in the background (``pytest &``)
    would hand down an ignored SIGINT, which Python then keeps ignoring."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize("sig,code", [("SIGINT", 130), ("SIGTERM", 143)])
def test_ctrl_c_keeps_the_finished_units_and_no_partial_one(units, tmp_path, sig, code):
    """Ctrl-C as a terminal sends it: SIGINT to the whole process group (the command and its
    local workers) once the first unit is reported finished; ``kill`` sends SIGTERM to the
    command alone. Either way (issue 21: "interrupting leaves finished units intact and no
    partial ones") the units reported finished are in place, each with its three files, no
    other unit folder and no staging folder is left, no fleet prior or summary is written,
    and the one line says how far it got and what is kept. (Earlier, every finished unit
    was discarded with the rest: hours of a large fleet lost to one Ctrl-C.)"""
    out = tmp_path / "D"
    proc = subprocess.Popen([sys.executable, "-m", "kincal", *_fleet_argv(
        units, out, "--workers", "2")], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, start_new_session=True, preexec_fn=_default_sigint)
    seen = []
    try:
        for line in proc.stderr:
            seen.append(line)
            if line.strip().startswith("unit 1/"):
                if sig == "SIGINT":
                    os.killpg(proc.pid, signal.SIGINT)
                else:
                    os.kill(proc.pid, signal.SIGTERM)
                break
        rest = proc.stderr.read()
        proc.wait(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    err = "".join(seen) + rest
    assert any(s.strip().startswith("unit 1/") for s in seen), err
    assert proc.returncode == code, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err  # workers too are quiet
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"kincal: error: interrupted ({sig}) after ") and \
        "finished are in place" in last and "fleet prior and summary were not" in last, last
    assert [s for s in err.splitlines() if s.startswith("kincal:")] == [last]  # one line
    finished = int(re.search(r"after (\d+) of the", last).group(1))
    assert 1 <= finished < N_UNITS, last  # the run was stopped midway, after a unit
    reported = re.findall(r"unit \d+/\d+: (\S+) calibrated", err)
    assert len(reported) >= 1 and len(reported) == finished, err  # every unit calibrates
    kept = sorted(p.name for p in out.iterdir())
    assert kept == sorted(reported), (kept, reported)  # no staging folder, no fleet file
    for name in kept:  # each complete: the three files, the URDF a whole document
        assert sorted(p.name for p in (out / name).iterdir()) == \
            ["FRAMES.json", "REPORT.json", "corrected.urdf"]
        assert (out / name / "corrected.urdf").read_text().rstrip().endswith("</robot>")
    assert f"the {finished} unit(s) finished" in last
    assert _gone(proc.pid, 30), "worker processes outlived the interrupted command"


@pytest.fixture(scope="module")
def local_run(units, tmp_path_factory):
    out = tmp_path_factory.mktemp("local") / "D"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalWarning)
        assert main(_fleet_argv(units[:6], out, "--workers", "1", "--quiet")) == 0
    return out


def test_a_running_scheduler_gives_the_local_results(units, local_run, tmp_path):
    from distributed import LocalCluster

    out = tmp_path / "D"
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", KincalWarning)
            assert main(_fleet_argv(units[:6], out, "--scheduler", cluster.scheduler_address,
                                    "--quiet")) == 0
    here, there = FleetPrior.read(local_run / "FLEET.json"), FleetPrior.read(out / "FLEET.json")
    assert here.units == there.units and here.names == there.names
    assert np.allclose(here.mean, there.mean, rtol=1e-9, atol=1e-15)
    assert np.allclose(here.covariance, there.covariance, rtol=1e-9, atol=1e-24)
    provenance = re.compile(r"<!--.*?-->", re.S)  # the command line and the time differ
    for n in here.units:
        got = provenance.sub("", (out / n / "corrected.urdf").read_text())
        assert got == provenance.sub("", (local_run / n / "corrected.urdf").read_text())
        assert "<joint" in got


@pytest.mark.parametrize("existing", [False, True])
def test_no_scheduler_at_the_address_is_one_line(units, tmp_path, capsys, existing):
    """A fleet that fails before any file is written leaves no folder behind (the one
    writer makes DIR with its first file), and a folder the user had as it was."""
    out = tmp_path / "D"
    if existing:
        out.mkdir()
        (out / "notes.txt").write_text("the user's")
    assert main(_fleet_argv(units[:2], out, "--scheduler", "tcp://127.0.0.1:9")) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("kincal: error: --scheduler tcp://127.0.0.1:9")
    if existing:
        assert [p.name for p in out.iterdir()] == ["notes.txt"]
        assert (out / "notes.txt").read_text() == "the user's"
    else:
        assert not out.exists()


@pytest.mark.parametrize("what", ["silent", "malformed", "http"])
def test_an_address_that_is_no_scheduler_is_one_line_in_bounded_time(units, tmp_path, capsys,
                                                                       monkeypatch, what):
    """A server that accepts and never answers (a web server's port, the dashboard's)
    made Dask's Client wait forever (its timeout bounds only the TCP connection, not the
    handshake); a malformed address (no port, another scheme) raised a traceback from deep
    in Dask. Each is one line naming the address, within the connect timeout, nothing
    written."""
    import socket
    import threading

    from kincal.fleet import engine

    monkeypatch.setattr(engine, "CONNECT_TIMEOUT", 1.0, raising=False)
    with socket.socket() as server:  # listens (the kernel accepts), never answers
        server.bind(("127.0.0.1", 0))
        server.listen()
        port = server.getsockname()[1]
        address = {"silent": f"tcp://127.0.0.1:{port}", "malformed": "127.0.0.1",
                   "http": f"http://127.0.0.1:{port}"}[what]
        out, got = tmp_path / "D", []
        t = threading.Thread(target=lambda: got.append(main(_fleet_argv(
            units[:2], out, "--scheduler", address))), daemon=True)
        t.start()
        t.join(30)
        assert not t.is_alive(), "kincal fleet --scheduler still waits after 30 s"
    assert got == [1]
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"kincal: error: --scheduler {address}: no Dask "
                                               "scheduler answers there"), err
    assert not out.exists()


def _half(x):
    if x == 3:
        raise ValueError("three")
    return x / 2


@pytest.mark.parametrize("batch", [1, 3, None])
def test_batched_tasks_report_every_job_and_each_error_alone(batch):
    from kincal.fleet.engine import Engine

    got, bad = [], []
    with Engine(1) as engine:
        engine.run(_half, list(range(10)), got.append, lambda job, e: bad.append((job, str(e))),
                   batch)
    assert sorted(got) == [x / 2 for x in range(10) if x != 3]
    assert bad == [(3, "three")]


def test_batch_size_spreads_units_over_the_workers():
    from kincal.fleet.engine import MAX_BATCH, TASKS_PER_WORKER, batch_size

    assert batch_size(5, 2) == 1
    assert batch_size(200, 2) == MAX_BATCH
    assert batch_size(40, 2) == 40 // (TASKS_PER_WORKER * 2)


def _stop(x):
    raise KeyboardInterrupt  # as Ctrl-C arrives in the command while results come in


def test_an_interrupted_engine_leaves_its_loggers_quiet():
    """After Ctrl-C (or SIGTERM) the engine's event loop may log errors of its own while the
    cancelled tasks wind down, after the command's one line (distributed's cancel callback
    raised a NameError there once): its loggers, children with levels of their own included
    (tornado.application), say nothing from then on. A plain exception leaves them as they
    were."""
    import logging

    from kincal.fleet.engine import Engine

    names = ("distributed", "tornado.application", "asyncio")
    before = {n: logging.getLogger(n).level for n in names}
    try:
        with pytest.raises(ValueError), Engine(1):
            raise ValueError("not an interrupt")
        assert all(logging.getLogger(n).isEnabledFor(logging.ERROR) for n in names)
        with pytest.raises(KeyboardInterrupt), Engine(1) as engine:
            engine.run(_half, list(range(4)), _stop)
        assert not any(logging.getLogger(n).isEnabledFor(logging.CRITICAL) for n in names)
    finally:
        for n, level in before.items():
            logging.getLogger(n).setLevel(level)


def test_a_ctrl_c_as_the_tasks_are_released_stops_the_run(monkeypatch):
    """Ctrl-C just after the last unit came back met Dask's Future.__del__ (a future's
    release, as run returned): Python prints an exception raised in __del__ as "Exception
    ignored" and drops it, so the command printed a KeyboardInterrupt traceback, went on and
    exited 0 with every file written. The engine releases its futures itself, where the
    interrupt propagates: here a release that meets one (as the signal would) stops the run."""
    import distributed

    from kincal.fleet.engine import Engine

    release, hit = distributed.Future.release, []

    def interrupted(self):
        if not hit:
            hit.append(self.key)
            raise KeyboardInterrupt
        return release(self)

    got = []
    with Engine(1) as engine:
        monkeypatch.setattr(distributed.Future, "release", interrupted)
        try:
            with pytest.raises(KeyboardInterrupt):
                engine.run(_half, [0, 1, 2, 4], got.append, batch=1)
        finally:
            monkeypatch.setattr(distributed.Future, "release", release)
    assert hit and sorted(got) == [0, 0.5, 1, 2]


def _worker_error():
    import logging

    logging.getLogger("distributed.worker").error("kincal-probe: scheduler gone")  # as the
    return True  # worker's heartbeat logs it when the command has closed the scheduler


def test_local_workers_print_no_engine_errors(capfd):
    """A local worker's own error logs (the heartbeat's "Failed to communicate with the
    scheduler", with its traceback, when Ctrl-C closed the scheduler under a busy worker)
    are not printed after the command's one line: failures reach the command through the
    tasks' results, which it reports itself."""
    import time

    from kincal.fleet.engine import Engine

    with Engine(1) as engine:
        assert all(engine.client.run(_worker_error).values())
        time.sleep(0.5)
    assert "kincal-probe" not in capfd.readouterr().err
