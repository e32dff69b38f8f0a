"""The client against a real server: meshes, sessions, constraints, drags,
named poses, exports, typed errors and WebSocket frames, sync and async."""

from __future__ import annotations

import asyncio
import struct

import numpy as np
import pytest

from dend_client import AsyncClient, Client, DendError, Frame, FrameError, decode_frame

N = 8


def grid(n: int = N):
    """An n×n unit grid in the z = 0 plane, two triangles per cell."""
    ij = np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="xy"), -1).reshape(-1, 2)
    positions = np.column_stack([ij[:, 0], ij[:, 1], np.zeros(n * n)]).astype(float)
    tris = []
    for j in range(n - 1):
        for i in range(n - 1):
            a = j * n + i
            tris += [[a, a + 1, a + n + 1], [a, a + n + 1, a + n]]
    return positions, np.array(tris)


def constraints(n: int = N):
    return {"fixed": list(range(n)), "handles": [{"name": "top", "vertices": list(range(n * (n - 1), n * n))}]}


def ready_session(c: Client):
    positions, tris = grid()
    mesh = c.upload_mesh(positions, tris)
    assert (mesh.vertices, mesh.triangles) == (N * N, len(tris))
    s = c.create_session(mesh.id)
    s.set_constraints(constraints())
    s.wait_ready()
    return s, positions


def test_drag_named_poses_and_errors(server: str) -> None:
    with Client(server) as c:
        s, rest = ready_session(c)
        p = s.drag("top", translate=(0, 0, 2), max_iters=200)
        assert p.positions.shape == (N * N, 3) and p.positions.dtype == np.float64
        assert p.positions[-1, 2] > 1.5, "the handle row moved up"
        assert np.allclose(p.positions[:N], rest[:N]), "the fixed row stayed"
        lift = s.save_pose("lift")
        assert (lift.name, lift.index) == ("lift", 0)
        saved = s.pose().positions
        s.drag("top", rotate=((1, 0, 0), 30), max_iters=200)
        s.save_pose("curl")
        # a name in use is refused unless replacing is asked for
        with pytest.raises(DendError) as e:
            s.save_pose("lift")
        assert (e.value.status, e.value.code) == (409, "pose_exists")
        np.testing.assert_array_equal(s.named_pose("lift").positions, saved)
        s.save_pose("curl", replace=True)
        assert [p.name for p in s.poses()] == ["lift", "curl"]
        assert [p["name"] for p in s.info()["poses"]] == ["lift", "curl"]
        np.testing.assert_array_equal(s.named_pose("lift").positions, saved)
        back = s.restore_pose("lift")
        np.testing.assert_array_equal(back.positions, saved)
        assert s.rename_pose("lift", "raised arm").name == "raised arm"
        with pytest.raises(DendError) as e:
            s.rename_pose("curl", "raised arm")
        assert (e.value.status, e.value.code) == (409, "pose_exists")
        with pytest.raises(DendError) as e:
            s.restore_pose("never saved")
        assert (e.value.status, e.value.code) == (404, "pose_not_found")
        with pytest.raises(DendError) as e:
            s.save_pose("  ")
        assert e.value.code == "invalid_pose_name"
        s.delete_pose("curl")
        assert [p.name for p in s.poses()] == ["raised arm"]
        # the restore was an undo step
        undone = s.undo()
        assert not np.array_equal(undone.positions, saved)
        obj = s.export("obj")
        assert obj.startswith(b"v ") or b"\nv " in obj
        with pytest.raises(DendError) as e:
            s.export("glb", morph_targets=True)
        assert e.value.code == "unsupported_export", "a JSON upload has no glTF asset"
        s.delete()


def test_websocket_frames_are_numpy(server: str) -> None:
    with Client(server) as c:
        s, rest = ready_session(c)
        with s.connect() as ws:
            state = ws.next_event("state")
            assert state["state"] == "ready"
            for seq in range(1, 6):
                ws.drag("top", seq=seq, translate=(0, 0, 0.2))
            f = ws.next_frame(ack_seq=5, settled=True)
            assert isinstance(f, Frame) and f.positions.shape == (N * N, 3)
            assert f.positions.dtype == np.float32
            np.testing.assert_allclose(f.positions, s.pose().positions, atol=1e-6)
            np.testing.assert_allclose(f.positions[-1, 2], 1.0, atol=0.05)
            ws.save_pose("from ws")
            ev = ws.next_event("state")
            while not ev["poses"]:
                ev = ws.next_event("state")
            assert ev["poses"][0]["name"] == "from ws"
            ws.send({"type": "restore_pose", "name": "missing"})
            with pytest.raises(DendError) as e:
                ws.next_event("never")
            assert e.value.code == "pose_not_found"


def test_frame_decoder_follows_the_header_version() -> None:
    n = 2
    pts = np.arange(6, dtype="<f4")
    frame = struct.pack("<4sHHQQIId", b"DEND", 2, 3, 7, 5, 9, n, 0.5) + pts.tobytes()
    f = decode_frame(frame)
    assert (f.version, f.revision, f.ack_seq, f.iteration, f.converged, f.settled) == (2, 7, 5, 9, True, True)
    np.testing.assert_array_equal(f.positions, pts.reshape(2, 3))
    with pytest.raises(FrameError, match="version 99"):
        decode_frame(b"DEND" + struct.pack("<H", 99) + frame[6:])
    with pytest.raises(FrameError):
        decode_frame(frame[:-1])
    with pytest.raises(FrameError):
        decode_frame(b"NOPE" + frame[4:])


def test_async_client(server: str) -> None:
    async def run() -> None:
        async with AsyncClient(server) as c:
            positions, tris = grid()
            mesh = await c.upload_mesh(positions, tris)
            s = await c.create_session(mesh.id)
            await s.set_constraints(constraints())
            await s.wait_ready()
            p = await s.drag("top", translate=(0, 0.5, 1), max_iters=200)
            await s.save_pose("a")
            assert [q.name for q in await s.poses()] == ["a"]
            np.testing.assert_array_equal((await s.named_pose("a")).positions, (await s.pose()).positions)
            ws = await s.connect()
            async with ws:
                await ws.drag("top", seq=1, translate=(0, 0, 0.1))
                f = await ws.next_frame(ack_seq=1, settled=True)
                assert f.positions.shape == p.positions.shape
            with pytest.raises(DendError) as e:
                await s.delete_pose("b")
            assert e.value.code == "pose_not_found"

    asyncio.run(run())


def test_the_readme_example_runs(server: str, capsys: pytest.CaptureFixture[str]) -> None:
    import pathlib
    import re

    readme = (pathlib.Path(__file__).resolve().parents[1] / "README.md").read_text()
    code = re.search(r"```python\n(.*?)```", readme, re.S).group(1)
    assert len(code.strip().splitlines()) <= 12
    scope: dict = {}
    exec(compile(code.replace("http://127.0.0.1:8080", server), "README.md", "exec"), scope)
    assert capsys.readouterr().out.startswith("['twist'] (")
    assert scope["pose"].positions.shape[1] == 3
