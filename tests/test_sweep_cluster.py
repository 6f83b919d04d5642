"""The documented cluster path for real: a Ray head started with ``ray start --head`` (token
authentication on, as Ray 2.60 starts it), a two-run sweep through ``RAY_ADDRESS`` with the
head's token shared the way the user guide (docs/guide.md) says, and the head stopped again.

Loopback only (127.0.0.1, free ports), its own temporary directory and token file (the
machine's ``~/.ray/auth_token`` is left alone), bounded in time; the head is started with
``--block`` so that stopping that one process (by its id) stops everything it started, and
no other Ray instance on the machine is touched.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import pytest
from sweep_support import QUICK

ROOT = Path(__file__).resolve().parent.parent
HEAD_START_S = 90  # at most, for the head to answer
SWEEP_S = 300  # at most, for the two runs


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _answers(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex(("127.0.0.1", port)) == 0


def _stop(head: subprocess.Popen) -> None:
    """Stop the head we started: SIGTERM to its ``ray start --block`` (which stops what it
    started), then its whole process group if it lingers."""
    if head.poll() is None:
        head.send_signal(signal.SIGTERM)
        try:
            head.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(head.pid, signal.SIGKILL)
            head.wait(timeout=10)
    try:  # daemons of the head left in its own process group
        os.killpg(head.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


@pytest.mark.accuracy
def test_a_sweep_through_ray_address_on_a_token_authenticated_head(tmp_path):
    ray_cli = Path(sys.executable).with_name("ray")
    if not ray_cli.is_file():
        pytest.skip("no ray command beside this Python")
    work = Path(tempfile.mkdtemp(prefix="pkmray", dir="/tmp"))  # short: Ray's socket paths
    token = work / "auth_token"
    token.write_text(uuid.uuid4().hex)
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    # the head's token, shared with the driver as the user guide says: the same file everywhere
    env |= {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN_PATH": str(token)}
    env.pop("PKM_ENGINE", None)
    port = _free_port()
    head_args = [
        str(ray_cli),
        "start",
        "--head",
        "--block",
        "--node-ip-address=127.0.0.1",
        f"--port={port}",
        f"--temp-dir={work / 'ray'}",
        "--num-cpus=2",
        "--include-dashboard=false",
        "--disable-usage-stats",
        f"--dashboard-agent-listen-port={_free_port()}",
        f"--dashboard-agent-grpc-port={_free_port()}",
        f"--runtime-env-agent-port={_free_port()}",
        f"--metrics-export-port={_free_port()}",
        f"--node-manager-port={_free_port()}",
        f"--object-manager-port={_free_port()}",
    ]
    log = open(work / "head.log", "wb")
    head = subprocess.Popen(
        head_args, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
    )
    try:
        end = time.monotonic() + HEAD_START_S
        while not _answers(port):
            assert head.poll() is None, (work / "head.log").read_text()[-2000:]
            assert time.monotonic() < end, "the Ray head did not answer in time"
            time.sleep(0.5)
        driver = env | {"RAY_ADDRESS": f"127.0.0.1:{port}", "PYTHONPATH": str(ROOT)}
        # the head asks for its token: a driver without it (no token file where it looks)
        # is refused, by name
        tokenless = {k: v for k, v in driver.items() if k != "RAY_AUTH_TOKEN_PATH"}
        refused = subprocess.run(
            [sys.executable, "-c", "import ray; ray.init()"],
            env=tokenless | {"HOME": str(work)},
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert refused.returncode != 0 and "AuthenticationError" in refused.stderr
        sets = [arg for s in QUICK for arg in ("--set", s)]
        cmd = [sys.executable, "-m", "scenarios", "sweep", "undeclared_effect", "--seeds", "2"]
        cmd += ["--over", "noise", "--engine", "ray", "--results", str(tmp_path), "--quiet"]
        done = subprocess.run(
            cmd + sets, env=driver, cwd=ROOT, capture_output=True, text=True, timeout=SWEEP_S
        )
        assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-4000:]
        s = json.loads((tmp_path / "undeclared_effect" / "sweep" / "summary.json").read_text())
        assert s["engine"] == "ray" and s["n_runs"] == 2 and s["n_failed"] == 0
        assert s["ray"] == {"address": f"127.0.0.1:{port}", "cpus": 2.0}  # the head's, joined
        assert s["metrics"]["residual_rms_after_mm"]["median"] > 0
        assert s["metrics"]["noise_floor_rms_mm"]["std"] == 0.0  # one tracker, two noise draws
    finally:
        _stop(head)
        log.close()
        shutil.rmtree(work, ignore_errors=True)
    assert head.poll() is not None and not _answers(port)
