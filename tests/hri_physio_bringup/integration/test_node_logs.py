"""The process group writes every process's whole output to a log file of its own."""

from __future__ import annotations

import io
import os
import stat
import sys
from pathlib import Path

import pytest

from hri_physio_bridge.launcher import ProcessGroup


def test_each_process_has_its_whole_output_in_its_log_file(tmp_path: Path,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    node = tmp_path / "chatty_node"
    node.write_text(f"#!{sys.executable}\n"
                    "import sys\n"
                    "print('[INFO] [1.0] [chatty]: hello', flush=True)\n"
                    "sys.stdout.buffer.write(b'bytes \\xff that are not UTF-8\\n'); sys.stdout.flush()\n"
                    "print('[WARN] [1.0] [chatty]: careful', file=sys.stderr, flush=True)\n"
                    "sys.stdout.write('no newline at the end'); sys.stdout.flush()\n")
    node.chmod(node.stat().st_mode | stat.S_IEXEC)
    monkeypatch.setenv("PATH", f"{tmp_path}{os.pathsep}{os.environ['PATH']}")
    seen: list[tuple[str, str]] = []
    console = io.StringIO()
    group = ProcessGroup(out=console, on_line=lambda name, line: seen.append((name, line)))
    log = tmp_path / "logs" / "chatty.log"
    log.parent.mkdir()
    p = group.start("chatty", "chatty_node", env=dict(os.environ), echo=False, log_path=log)
    assert group.wait_any_exit(30) is p
    assert group.stop() == {"chatty": 0}
    expected = ["[INFO] [1.0] [chatty]: hello", "bytes \ufffd that are not UTF-8",
                "[WARN] [1.0] [chatty]: careful", "no newline at the end"]
    assert log.read_text(encoding="utf-8").splitlines() == expected
    assert log.read_text(encoding="utf-8").endswith("\n")
    assert seen == [("chatty", line) for line in expected]
    assert console.getvalue() == ""  # not echoed: the console shows what the launcher chooses
    assert p.log_path == log
