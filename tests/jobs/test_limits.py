"""A descriptor job runs in a child process under a time and a memory limit: over
either it fails with a code and a sentence, a refused mesh keeps its code, and a
crash is raised so that the queue retries it."""

from __future__ import annotations

import pickle
import signal
import subprocess
import sys

import numpy as np
import pytest
from conftest import EXAMPLES, example

from worker.engine.descriptor import ShapeDescriptor
from worker.engine.pipeline import describe_file
from worker.engine.presets import get_preset
from worker.jobs.limits import describe_limited, outcome_of
from worker.jobs.previews import IMPORTS as PREVIEW_IMPORTS

pytestmark = pytest.mark.slow  # each describes a mesh in a fresh child process

MESH = example("quadruped-0")
GB = 1024**3


def test_within_the_limits_the_descriptor_and_the_previews_come_back():
    outcome = describe_limited(
        MESH,
        MESH.name,
        "smeets2010-shrec",
        max_faces=10**6,
        time_limit=120,
        memory_limit_bytes=4 * GB,
    )
    assert outcome.code is None and outcome.descriptor is not None
    assert ShapeDescriptor.from_npz_bytes(outcome.descriptor).vertices > 2000
    assert outcome.preview is not None and outcome.preview[:4] == b"glTF"
    assert outcome.thumbnail is not None and outcome.thumbnail[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_query_gets_the_same_descriptor_and_its_preview_but_no_thumbnail():
    outcome = describe_limited(
        MESH, MESH.name, "smeets2010-shrec", max_faces=10**6, time_limit=120,
        memory_limit_bytes=4 * GB, with_thumbnail=False,
    )  # fmt: skip
    assert outcome.preview is not None and outcome.thumbnail is None
    described = ShapeDescriptor.from_npz_bytes(outcome.descriptor)
    direct = describe_file(MESH, get_preset("smeets2010-shrec"))
    for modality in ("gdm", "ddt", "spectrum"):
        np.testing.assert_array_equal(getattr(described, modality), getattr(direct, modality))


def test_over_the_time_limit_the_job_fails_with_a_sentence():
    outcome = describe_limited(
        MESH, MESH.name, "smeets2010-shrec", max_faces=10**6, time_limit=0.5, memory_limit_bytes=0
    )
    assert outcome.descriptor is None and outcome.code == "describe_timeout"
    assert "longer than this service's limit of 0.5 seconds" in str(outcome.message)


def test_over_the_memory_limit_the_job_fails_with_a_sentence():
    outcome = describe_limited(
        MESH, MESH.name, "smeets2010-shrec", max_faces=10**6, time_limit=120,
        memory_limit_bytes=300 * 1024**2,
    )  # fmt: skip
    assert outcome.descriptor is None and outcome.code == "describe_out_of_memory", outcome
    assert "300 MB" in str(outcome.message)


def test_a_mesh_error_keeps_its_code_and_a_crash_is_raised_for_a_retry():
    outcome = describe_limited(
        MESH, MESH.name, "smeets2010-shrec", max_faces=10, time_limit=30, memory_limit_bytes=0
    )
    assert outcome.code == "too_many_faces" and "the limit is 10" in str(outcome.message)
    with pytest.raises(RuntimeError, match="FileNotFoundError"):
        describe_limited(
            EXAMPLES / "missing.off.gz", "m.off.gz", "smeets2010-shrec", max_faces=10,
            time_limit=30, memory_limit_bytes=0,
        )  # fmt: skip


def test_a_child_killed_from_outside_is_retried_not_taken_for_a_lack_of_memory():
    """SIGKILL (the kernel's out-of-memory killer, an operator) says nothing about the
    mesh: retried. Dying of another signal under the memory cap is the mesh's need for
    memory; so is a MemoryError the child reports."""
    cap = 4096 * 1024**2
    with pytest.raises(RuntimeError, match="killed"):
        outcome_of(b"", -signal.SIGKILL, cap)
    assert outcome_of(b"", -signal.SIGSEGV, cap).code == "describe_out_of_memory"
    assert outcome_of(pickle.dumps(("out_of_memory", "")), 1, cap).code == "describe_out_of_memory"
    with pytest.raises(RuntimeError, match="exited with code -11"):
        outcome_of(b"", -signal.SIGSEGV, 0)  # no cap: a crash


def test_a_consumer_can_start_its_fork_server_before_the_first_job():
    # In a fresh interpreter: this test process may have started one already.
    script = (
        "import os\n"
        "import time\n"
        "from pathlib import Path\n"
        "from worker.jobs.limits import start_fork_server\n"
        "start_fork_server()\n"
        "def children():\n"
        "    for stat in Path('/proc').glob('[0-9]*/stat'):\n"
        "        try:\n"
        "            fields = stat.read_text().rsplit(')', 1)[1].split()\n"
        "            command = (stat.parent / 'cmdline').read_bytes()\n"
        "        except OSError:\n"
        "            continue\n"
        "        if int(fields[1]) == os.getpid():\n"
        "            yield command.replace(b'\\0', b' ').decode()\n"
        # The server is forked, then execs: until it has, its command line is not its own.
        "for _ in range(100):\n"
        "    listed = list(children())\n"
        "    if any('forkserver' in command for command in listed):\n"
        "        break\n"
        "    time.sleep(0.05)\n"
        "print('\\n'.join(listed))\n"
    )
    children = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True, timeout=60
    ).stdout
    assert "forkserver" in children


def test_a_job_starts_with_the_engine_and_the_previews_libraries_imported(tmp_path):
    # In a fresh interpreter, a job's process from the fork server reports its modules:
    # what the server preloaded, a job does not import again (0.4 s a job for the previews).
    report = tmp_path / "modules.txt"
    # (The fork server is one per process: any forkserver context's process comes from it.)
    script = (
        "import multiprocessing\n"
        "from worker.jobs.limits import start_fork_server\n"
        "start_fork_server()\n"
        "code = 'import sys; open(%r, \"w\").write(chr(10).join(sys.modules))'\n"
        "context = multiprocessing.get_context('forkserver')\n"
        f"child = context.Process(target=exec, args=(code % {str(report)!r},))\n"
        "child.start()\n"
        "child.join()\n"
    )
    subprocess.run([sys.executable, "-c", script], check=True, timeout=120)
    modules = set(report.read_text().split("\n"))
    assert {"worker.engine.pipeline", "worker.jobs.previews", *PREVIEW_IMPORTS} <= modules
