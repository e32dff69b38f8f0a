"""Starts a real `dend serve` on a free port for the tests: the binary from
$DEND_BIN, else the repository's target/debug/dend (built by `cargo
build` or `cargo test`)."""

from __future__ import annotations

import os
import pathlib
import subprocess
import threading
from typing import Iterator

import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]


def dend_bin() -> pathlib.Path:
    env = os.environ.get("DEND_BIN")
    if env:
        return pathlib.Path(env)
    target = os.environ.get("CARGO_TARGET_DIR", str(REPO / "target"))
    return pathlib.Path(target) / "debug" / "dend"


@pytest.fixture(scope="session")
def server() -> Iterator[str]:
    exe = dend_bin()
    if not exe.is_file():
        pytest.fail(f"no dend binary at {exe}: run `cargo build` first or set DEND_BIN")
    proc = subprocess.Popen(
        [str(exe), "serve", "--addr", "127.0.0.1:0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env={**os.environ, "RUST_LOG": "warn"},
    )
    assert proc.stdout is not None
    url = None
    for line in proc.stdout:
        if line.startswith("listening on "):
            url = line.split("listening on ", 1)[1].strip()
            break
    if url is None:
        proc.kill()
        pytest.fail("dend serve exited before printing its URL")
    # keep draining stdout so the server never blocks on a full pipe
    threading.Thread(target=lambda: [None for _ in proc.stdout], daemon=True).start()
    try:
        yield url
    finally:
        proc.terminate()
        proc.wait(timeout=10)
