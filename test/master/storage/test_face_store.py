"""Tests of the persistent face memory: round trip, permissions, secure forgetting, retention, corruption
recovery, kill -9 durability, process lock and the ``face-reid-faces`` CLI."""

from __future__ import annotations

import contextlib
import json
import logging
import os
import signal
import sqlite3
import stat
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO_ROOT

from face_reid_master.identity.bayes_table import BayesIdentityManager
from face_reid_master.identity.records import LearnedFace
from face_reid_master.storage.face_store import (
    FaceStore,
    FaceStoreError,
    FaceStoreLockedError,
    FaceSummary,
    default_db_path,
)
from face_reid_master.tools.faces_cli import main as cli_main

REPO_ROOT = REPO_ROOT
DIM = 128


def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def _feats(seed: int, k: int = 50) -> np.ndarray:
    return np.random.default_rng(seed).normal(0.0, 0.1, (k, DIM)).astype(np.float32)


def _distinctive(tag: float, k: int = 50) -> np.ndarray:
    """Vectors whose raw bytes cannot occur by chance in the file."""
    return (tag + np.arange(k * DIM, dtype=np.float64).reshape(k, DIM) * 1e-3).astype(np.float32)


def _raw_files(db: Path) -> dict[str, bytes]:
    out = {}
    for suffix in ("", "-wal", "-shm"):
        p = Path(str(db) + suffix)
        if p.exists():
            out[p.name] = p.read_bytes()
    return out


def _contains_any(db: Path, feats: np.ndarray) -> list[str]:
    """Names of the database files holding the bytes of any row of ``feats``."""
    rows = [np.ascontiguousarray(r, dtype="<f4").tobytes() for r in feats]
    return [name for name, data in _raw_files(db).items() if any(r in data for r in rows)]


@pytest.fixture
def db(tmp_path: Path) -> Path:
    return tmp_path / "store" / "faces.db"


# ------------------------------------------------------------------------------------------------
# Round trip
# ------------------------------------------------------------------------------------------------
def test_round_trip_is_exact_and_survives_reopening(db: Path) -> None:
    special = _feats(3, 4)
    special[0, :4] = [np.float32(1e-45), -0.0, np.finfo(np.float32).max, np.float32(0.1)]  # subnormal, -0
    faces = [
        LearnedFace(1, _feats(1), None, 1_700_000_000.123456, 1_700_000_100.654321, 57),
        LearnedFace(2, special, "Zoë Ünicode 名前", 12.5, 99.25, 3),
        LearnedFace(7, _feats(7, 1), "Ada", 0.0, 0.0, 0),
    ]
    with FaceStore(db) as store:
        assert store.recovered_from is None
        store.save_face(faces[0])
        assert store.save_faces(faces[1:]) == 2
        assert store.save_faces([]) == 0
    with FaceStore(db) as store:
        loaded = store.load_faces()
        summaries = store.list_faces()
    assert [f.face_id for f in loaded] == [1, 2, 7]
    for a, b in zip(faces, loaded, strict=True):
        assert b.features.dtype == np.float32 and b.features.shape == a.features.shape
        assert b.features.tobytes() == a.features.tobytes()  # bit-exact, -0.0 and subnormals included
        assert (b.name, b.created_s, b.last_seen_s, b.n_observations) == (
            a.name,
            a.created_s,
            a.last_seen_s,
            a.n_observations,
        )
    assert summaries == [
        FaceSummary(1, None, 50, 57, 1_700_000_000.123456, 1_700_000_100.654321),
        FaceSummary(2, "Zoë Ünicode 名前", 4, 3, 12.5, 99.25),
        FaceSummary(7, "Ada", 1, 0, 0.0, 0.0),
    ]


def test_save_face_replaces_row_and_all_features(db: Path) -> None:
    with FaceStore(db) as store:
        store.save_face(LearnedFace(3, _feats(1, 50), None, 1.0, 2.0, 10))
        store.save_face(LearnedFace(3, _feats(2, 20), "Bob", 1.0, 5.0, 30))
        (face,) = store.load_faces()
        assert face.features.tobytes() == _feats(2, 20).tobytes()
        assert (face.name, face.last_seen_s, face.n_observations) == ("Bob", 5.0, 30)
        assert store.list_faces()[0].n_features == 20


def test_identity_manager_export_import_through_the_store(db: Path) -> None:
    rng = np.random.default_rng(5)
    centre = np.zeros(DIM, np.float32)
    centre[0] = 0.7
    m = BayesIdentityManager(min_observations=2)
    for t in range(2):
        m.add_observations(1, (centre + rng.normal(0, 0.02, (1, DIM))).astype(np.float32), t)
        m.step(t)
    m.faces.set_name(1, "Eve")
    with FaceStore(db) as store:
        store.save_faces(m.faces.export_all())
    fresh = BayesIdentityManager(min_observations=2)
    with FaceStore(db) as store:
        fresh.faces.import_faces(store.load_faces())
    assert fresh.face_ids() == [1] and fresh.faces.name(1) == "Eve"
    assert fresh.faces.features(1).tobytes() == m.faces.features(1).tobytes()


def test_bad_input_raises_clear_errors(db: Path) -> None:
    with FaceStore(db) as store:
        with pytest.raises(ValueError, match="dim 64"):
            store.save_face(LearnedFace(1, np.zeros((2, 64), np.float32)))
        with pytest.raises(ValueError, match="LearnedFace"):
            store.save_face((1, np.zeros((2, DIM))))  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="duplicate"):
            store.save_faces([LearnedFace(1, _feats(1, 2)), LearnedFace(1, _feats(2, 2))])
        assert store.load_faces() == []  # nothing of the failed batch was written
        with pytest.raises(ValueError):
            store.set_name(True, "x")  # type: ignore[arg-type]
        with pytest.raises(ValueError):
            store.set_name(1, 5)  # type: ignore[arg-type]
        with pytest.raises(ValueError):
            store.forget_name("")
        with pytest.raises(ValueError):
            store.prune_unnamed(float("nan"))
    with pytest.raises(ValueError):
        FaceStore(db, retention_unnamed_s=0.0)
    with pytest.raises(ValueError):
        FaceStore(db, synchronous="OFF")
    with pytest.raises(ValueError):
        FaceStore("")
    store = FaceStore(db)
    store.close()
    store.close()  # idempotent
    with pytest.raises(FaceStoreError, match="closed"):
        store.load_faces()


def test_embedding_dim_mismatch_is_an_error_not_a_recovery(db: Path) -> None:
    with FaceStore(db) as store:
        store.save_face(LearnedFace(1, _feats(1, 3)))
    with pytest.raises(FaceStoreError, match="128-dimensional"):
        FaceStore(db, embedding_dim=64)
    with FaceStore(db, embedding_dim=None) as store:  # adopt the stored dimension (CLI)
        assert store.embedding_dim == DIM and store.recovered_from is None
        assert len(store.load_faces()) == 1


def test_saving_again_rewrites_only_the_rows_that_changed(db: Path) -> None:
    feats = _feats(1, 50)
    with FaceStore(db) as store:
        store.save_face(LearnedFace(3, feats, None, 1.0, 2.0, 10))
        conn = store._db  # the store's own connection: how many rows its statements changed
        before = conn.total_changes
        feats = feats.copy()
        feats[[4, 31]] = _feats(2, 2)  # the feature bank replaces single rows
        store.save_face(LearnedFace(3, feats, None, 1.0, 3.0, 11))
        assert conn.total_changes - before <= 4  # the face row, 2 feature rows, the id high-water mark
        assert store.load_faces()[0].features.tobytes() == feats.tobytes()
        before = conn.total_changes
        store.save_face(LearnedFace(3, feats.copy(), None, 1.0, 3.5, 12))  # features unchanged: counters only
        assert conn.total_changes - before <= 2
        assert store.list_faces()[0].n_observations == 12
        store.save_face(LearnedFace(3, feats[:30], None, 1.0, 4.0, 12))  # fewer rows
        assert store.load_faces()[0].features.tobytes() == feats[:30].tobytes()
        store.save_face(LearnedFace(3, feats[:40], None, 1.0, 5.0, 13))  # more rows
        assert store.load_faces()[0].features.tobytes() == feats[:40].tobytes()
        with sqlite3.connect(db) as other:  # someone else removed rows: everything is written again
            other.execute("DELETE FROM features WHERE face_id = 3 AND idx < 5")
        store.save_face(LearnedFace(3, feats[:40], None, 1.0, 6.0, 14))
        assert store.load_faces()[0].features.tobytes() == feats[:40].tobytes()
        store.forget(3)
        store.save_face(LearnedFace(3, feats[:10], None, 1.0, 7.0, 1))  # forgotten, then saved anew: in full
        assert store.load_faces()[0].features.tobytes() == feats[:10].tobytes()
    with FaceStore(db) as store:
        assert store.load_faces()[0].features.tobytes() == feats[:10].tobytes()


def test_store_is_single_thread(db: Path) -> None:
    with FaceStore(db) as store:
        errors: list[BaseException] = []

        def other_thread() -> None:
            try:
                store.save_face(LearnedFace(1, _feats(1, 2)))
            except BaseException as exc:
                errors.append(exc)

        t = threading.Thread(target=other_thread)
        t.start()
        t.join()
        assert len(errors) == 1 and isinstance(errors[0], (FaceStoreError, sqlite3.ProgrammingError))
        assert store.load_faces() == []


# ------------------------------------------------------------------------------------------------
# Permissions and the process lock
# ------------------------------------------------------------------------------------------------
def test_files_are_private_even_with_a_permissive_umask(db: Path) -> None:
    old = os.umask(0)
    try:
        with FaceStore(db) as store:
            store.save_face(LearnedFace(1, _feats(1)))
            wal = Path(str(db) + "-wal")
            shm = Path(str(db) + "-shm")
            assert wal.exists() and shm.exists()
            assert _mode(db) == 0o600 and _mode(wal) == 0o600 and _mode(shm) == 0o600
            assert _mode(db.parent) == 0o700
    finally:
        os.umask(old)


def test_broader_permissions_are_fixed_with_a_warning(db: Path, caplog: pytest.LogCaptureFixture) -> None:
    with FaceStore(db) as store:
        store.save_face(LearnedFace(1, _feats(1)))
    os.chmod(db, 0o644)
    with caplog.at_level(logging.WARNING, logger="face_reid_master.storage.face_store"), FaceStore(db) as store:
        assert _mode(db) == 0o600
        assert len(store.load_faces()) == 1 and store.recovered_from is None
    assert any("644" in r.getMessage() and r.levelno == logging.WARNING for r in caplog.records)


def test_second_process_or_instance_is_locked_out(db: Path) -> None:
    with FaceStore(db) as store:
        store.save_face(LearnedFace(1, _feats(1, 2)))
        with pytest.raises(FaceStoreLockedError, match="in use"):
            FaceStore(db)
        assert cli_main(["--db", str(db), "forget", "1"]) == 3
        assert store.face_ids() == [1]
    with FaceStore(db) as store:  # released on close
        assert store.face_ids() == [1]


# ------------------------------------------------------------------------------------------------
# Forgetting: rows and bytes gone
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("how", ["forget", "forget_name", "prune"])
def test_forgotten_vectors_are_gone_from_every_file(db: Path, how: str) -> None:
    versions = [_distinctive(1000.0 + v) for v in range(3)]
    with FaceStore(db, retention_unnamed_s=10.0) as store:
        for i in range(1, 31):
            if i != 7:
                store.save_face(LearnedFace(i, _feats(i), f"p{i}", 0.0, 100.0, 5))
        for v in versions:  # updated several times: old versions sit in WAL frames / freed cells
            store.save_face(LearnedFace(7, v, None if how == "prune" else "Target", 0.0, 50.0, 9))
        assert _contains_any(db, versions[-1])  # sanity: the grep finds stored vectors
        if how == "forget":
            assert store.forget(7) is True
            assert store.forget(7) is False
        elif how == "forget_name":
            assert store.forget_name("Target") == [7]
            assert store.forget_name("Target") == []
        else:
            assert store.prune_unnamed(100.0) == [7]
        assert 7 not in store.face_ids() and len(store.face_ids()) == 29
        raw = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
        try:
            assert raw.execute("SELECT COUNT(*) FROM features WHERE face_id = 7").fetchone()[0] == 0
        finally:
            raw.close()
        for v in versions:
            assert _contains_any(db, v) == []
        assert Path(str(db) + "-wal").stat().st_size == 0
        assert _contains_any(db, _feats(8)) == ["faces.db"]  # the others are intact (in the main file)
        assert store.integrity_ok()
        assert store.max_face_id() == 30  # the high-water mark survives the deletion
    with FaceStore(db) as store:
        assert 7 not in store.face_ids() and len(store.load_faces()) == 29


def test_forget_name_deletes_all_faces_with_exactly_that_name(db: Path) -> None:
    with FaceStore(db) as store:
        store.save_faces(
            [
                LearnedFace(1, _feats(1, 2), "Ann"),
                LearnedFace(2, _feats(2, 2), "ann"),
                LearnedFace(3, _feats(3, 2), "Ann"),
                LearnedFace(4, _feats(4, 2)),
            ]
        )
        assert store.forget_name("Ann") == [1, 3]
        assert store.face_ids() == [2, 4]
        assert store.set_name(4, "Ann") is True and store.set_name(9, "x") is False
        assert store.set_name(2, None) is True
        assert [(s.face_id, s.name) for s in store.list_faces()] == [(2, None), (4, "Ann")]


# ------------------------------------------------------------------------------------------------
# Retention
# ------------------------------------------------------------------------------------------------
def test_retention_prunes_only_old_unnamed_faces(db: Path) -> None:
    faces = [
        LearnedFace(1, _feats(1, 2), None, 0.0, 800.0),  # unnamed, not seen for 200 s: pruned
        LearnedFace(2, _feats(2, 2), None, 0.0, 950.0),  # unnamed, recent: kept
        LearnedFace(3, _feats(3, 2), "Named", 0.0, 0.0),  # named: kept forever
        LearnedFace(4, _feats(4, 2), None, 0.0, 10.0),  # old but carried by a live track: kept
        LearnedFace(5, _feats(5, 2), None, 0.0, 899.0),  # just past the limit: pruned
        LearnedFace(6, _feats(6, 2), None, 0.0, 900.0),  # exactly at the limit: kept
    ]
    with FaceStore(db, retention_unnamed_s=100.0) as store:
        store.save_faces(faces)
        assert store.prune_unnamed(1000.0, keep=[4]) == [1, 5]
        assert store.face_ids() == [2, 3, 4, 6]
        assert store.prune_unnamed(1000.0, keep=[4]) == []
    with FaceStore(db) as store:  # retention None: keep forever
        assert store.prune_unnamed(1e12) == [] and store.face_ids() == [2, 3, 4, 6]


# ------------------------------------------------------------------------------------------------
# Corruption: backed up, fresh store, never a crash
# ------------------------------------------------------------------------------------------------
def _assert_recovered(db: Path, store: FaceStore, original: bytes, caplog: pytest.LogCaptureFixture) -> None:
    backup = store.recovered_from
    assert backup is not None and backup.parent == db.parent
    assert backup.name.startswith("faces.db.corrupt-") and backup.name.endswith("Z")
    assert backup.read_bytes() == original and _mode(backup) == 0o600
    assert store.load_faces() == [] and store.integrity_ok()
    store.save_face(LearnedFace(1, _feats(1, 2)))  # the fresh store works
    assert [f.face_id for f in store.load_faces()] == [1]
    assert _mode(db) == 0o600
    assert any(r.levelno == logging.ERROR and "CORRUPT" in r.getMessage() for r in caplog.records)


def test_garbage_file_is_moved_aside(db: Path, caplog: pytest.LogCaptureFixture) -> None:
    db.parent.mkdir(parents=True)
    garbage = b"this is not an SQLite database \x00\xff" * 300
    db.write_bytes(garbage)
    os.chmod(db, 0o644)
    Path(str(db) + "-wal").write_bytes(b"stale wal")  # must move with it, never be replayed
    with caplog.at_level(logging.WARNING), FaceStore(db) as store:
        _assert_recovered(db, store, garbage, caplog)
        assert Path(str(store.recovered_from) + "-wal").read_bytes() == b"stale wal"


def test_truncated_database_is_moved_aside(db: Path, caplog: pytest.LogCaptureFixture) -> None:
    with FaceStore(db) as store:
        store.save_faces(LearnedFace(i, _feats(i)) for i in range(1, 41))
    size = db.stat().st_size
    assert size > 500_000
    with open(db, "r+b") as fh:
        fh.truncate(size // 2)
    truncated = db.read_bytes()
    with caplog.at_level(logging.WARNING), FaceStore(db) as store:
        _assert_recovered(db, store, truncated, caplog)


@pytest.mark.parametrize("kind", ["schema_version", "foreign_tables"])
def test_unknown_schema_is_moved_aside(db: Path, kind: str, caplog: pytest.LogCaptureFixture) -> None:
    if kind == "schema_version":
        with FaceStore(db) as store:
            store.save_face(LearnedFace(1, _feats(1, 2)))
        conn = sqlite3.connect(db)
        conn.execute("UPDATE meta SET value = '99' WHERE key = 'schema_version'")
    else:
        db.parent.mkdir(parents=True)
        conn = sqlite3.connect(db)
        conn.execute("CREATE TABLE something_else (x INTEGER)")
    conn.commit()
    conn.close()
    original = db.read_bytes()
    with caplog.at_level(logging.WARNING), FaceStore(db) as store:
        _assert_recovered(db, store, original, caplog)


def test_empty_existing_file_is_a_valid_new_store(db: Path) -> None:
    db.parent.mkdir(parents=True)
    db.touch(mode=0o600)
    with FaceStore(db) as store:
        assert store.recovered_from is None and store.load_faces() == []


# ------------------------------------------------------------------------------------------------
# kill -9 durability
# ------------------------------------------------------------------------------------------------
_WRITER = """
import sys
import numpy as np
from face_reid_master.storage.face_store import FaceStore
from face_reid_master.identity.records import LearnedFace

store = FaceStore(sys.argv[1], synchronous=sys.argv[2])
for i in range(1, 100_000):
    feats = np.random.default_rng(i).normal(0.0, 0.1, (50, 128)).astype(np.float32)
    store.save_face(LearnedFace(i, feats, f"p{i}", float(i), float(i) + 0.5, i))
    print(f"saved {i}", flush=True)
"""


@pytest.mark.parametrize("synchronous", ["FULL", "NORMAL"])
def test_everything_committed_survives_kill_9(db: Path, synchronous: str) -> None:
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT), "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-c", _WRITER, str(db), synchronous],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    watchdog = threading.Timer(60.0, proc.kill)
    watchdog.start()
    try:
        assert proc.stdout is not None
        acknowledged = 0
        while acknowledged < 5:
            line = proc.stdout.readline()
            assert line, f"writer died early: {proc.stderr.read() if proc.stderr else ''}"
            acknowledged = int(line.split()[1])
        proc.send_signal(signal.SIGKILL)  # mid-write: the writer keeps saving in a tight loop
        proc.wait(timeout=30)
    finally:
        watchdog.cancel()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    raw = sqlite3.connect(db)
    try:
        assert raw.execute("PRAGMA integrity_check").fetchall() == [("ok",)]
    finally:
        raw.close()
    with FaceStore(db) as store:
        assert store.recovered_from is None
        faces = store.load_faces()
    ids = [f.face_id for f in faces]
    assert len(ids) >= acknowledged and ids == list(range(1, len(ids) + 1))  # every acknowledged save
    for f in faces:
        expected = np.random.default_rng(f.face_id).normal(0.0, 0.1, (50, 128)).astype(np.float32)
        assert f.features.tobytes() == expected.tobytes()
        assert (f.name, f.created_s, f.n_observations) == (f"p{f.face_id}", float(f.face_id), f.face_id)


# ------------------------------------------------------------------------------------------------
# Default path and CLI
# ------------------------------------------------------------------------------------------------
def test_default_db_path(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("FACE_REID_DB", str(tmp_path / "x.db"))
    assert default_db_path() == tmp_path / "x.db"
    monkeypatch.delenv("FACE_REID_DB")
    monkeypatch.delenv("XDG_DATA_HOME", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    assert default_db_path() == tmp_path / ".local" / "share" / "face_reid" / "faces.db"
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    assert default_db_path() == tmp_path / "xdg" / "face_reid" / "faces.db"


def _cli_store(db: Path) -> None:
    with FaceStore(db) as store:
        store.save_faces(
            [
                LearnedFace(1, _feats(1, 3), "Ann", 1_700_000_000.0, 1_700_000_060.0, 12),
                LearnedFace(2, _feats(2, 5), None, 1_700_000_100.0, 1_700_000_200.0, 40),
                LearnedFace(3, _feats(3, 1), "Ann", 1_700_000_300.0, 1_700_000_300.0, 1),
            ]
        )


@contextlib.contextmanager
def _time_zone(tz: str) -> Iterator[None]:
    """This process's local time zone is ``tz`` (a POSIX TZ string) inside the block."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("TZ", tz)
        time.tzset()
        try:
            yield
        finally:
            patch.undo()
            time.tzset()


def test_cli_list(db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _cli_store(db)
    with _time_zone("CET-1"):  # times are shown in local time, with the offset
        assert cli_main(["--db", str(db), "list"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert lines[0].split()[-6:] == ["(local", "time)", "last", "seen", "(local", "time)"]
    assert lines[1].split() == ["1", "Ann", "3", "12", "2023-11-14T23:13:20+01:00", "2023-11-14T23:14:20+01:00"]
    assert lines[2].split()[:4] == ["2", "-", "5", "40"]
    assert "3 face(s)" in out
    assert cli_main(["--db", str(db), "list", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert [d["face_id"] for d in data] == [1, 2, 3]
    assert data[1] == {
        "face_id": 2,
        "name": None,
        "n_features": 5,
        "n_observations": 40,
        "created_s": 1_700_000_100.0,
        "last_seen_s": 1_700_000_200.0,
    }
    assert all("vector" not in d and "features" not in d for d in data)


def test_a_masters_list_shows_times_as_the_store_list_does(db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """face-reid-faces --master prints the ~/list_faces answer (seconds since the epoch) in the same local ISO
    format as the store's list, not as a number of seconds."""
    from face_reid_master.tools.faces_remote import format_remote_list

    _cli_store(db)
    with _time_zone("CET-1"):
        assert cli_main(["--db", str(db), "list"]) == 0
        remote = format_remote_list([(1, "Ann", 3, 1_700_000_060.0), (2, "", 5, 1_700_000_200.0)], "/face_reid_master")
    stored = capsys.readouterr().out.splitlines()
    lines = remote.splitlines()
    assert lines[0].endswith("last seen (local time)") and stored[0].endswith("last seen (local time)")
    assert lines[1].split() == ["1", "Ann", "3", "2023-11-14T23:14:20+01:00"]
    assert lines[1].split()[-1] == stored[1].split()[-1] and lines[2].split()[-1] == stored[2].split()[-1]
    assert lines[-1] == "2 face(s) on /face_reid_master"


def test_cli_forget_and_rename(db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _cli_store(db)
    assert cli_main(["--db", str(db), "forget", "2"]) == 0
    assert "forgot face 2" in capsys.readouterr().out
    assert cli_main(["--db", str(db), "forget", "2"]) == 1
    assert "no face 2" in capsys.readouterr().err
    assert cli_main(["--db", str(db), "rename", "3", "Bea"]) == 0
    assert cli_main(["--db", str(db), "forget", "--name", "Ann"]) == 0
    assert "forgot face(s) 1 named 'Ann'" in capsys.readouterr().out
    assert cli_main(["--db", str(db), "forget", "--name", "Ann"]) == 1
    assert cli_main(["--db", str(db), "rename", "3", "--clear"]) == 0
    assert cli_main(["--db", str(db), "rename", "9", "X"]) == 1
    assert cli_main(["--db", str(db), "rename", "3", "  "]) == 2
    with FaceStore(db) as store:
        assert [(s.face_id, s.name) for s in store.list_faces()] == [(3, None)]


def test_cli_errors(db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "nope" / "faces.db"
    assert cli_main(["--db", str(missing), "list"]) == 4
    assert "no face store" in capsys.readouterr().err
    assert not missing.exists() and not missing.parent.exists()  # the CLI never creates a store
    assert cli_main(["--db", str(db), "forget"]) == 2  # neither an id nor --name
    assert cli_main(["--db", str(db), "forget", "1", "--name", "x"]) == 2
    assert cli_main(["--db", str(db), "bogus"]) == 2
    assert cli_main(["--help"]) == 0


@pytest.mark.parametrize(("fifo", "code", "said"), [
    ("faces.db", 4, "face store {dir}/faces.db is not a regular file (a FIFO)"),
    ("faces.db-wal", 4, "face store file {dir}/faces.db-wal is not a regular file (a FIFO): refused"),
    ("faces.db.ids", 0, "the id ledger {dir}/faces.db.ids is not a regular file"),
])
def test_a_fifo_in_place_of_a_store_file_is_refused_not_waited_on(db: Path, fifo: str, code: int, said: str) -> None:
    db.parent.mkdir(mode=0o700)
    if fifo != "faces.db":
        FaceStore(db).close()
    for stale in (db, Path(f"{db}-wal"), Path(f"{db}.ids")):
        if stale.name == fifo:
            stale.unlink(missing_ok=True)
    os.mkfifo(db.parent / fifo, 0o600)
    try:  # before: the open waited for a writer of the FIFO forever
        done = subprocess.run([sys.executable, "-m", "face_reid_master.tools.faces_cli", "--db", str(db), "list"],
                              cwd=REPO_ROOT, capture_output=True, text=True, timeout=30)
    except subprocess.TimeoutExpired:
        pytest.fail(f"face-reid-faces list hung on a FIFO as {fifo}")
    assert done.returncode == code, done.stderr
    assert said.format(dir=db.parent) in done.stderr and len(done.stderr.splitlines()) == 1, done.stderr


def test_an_invalid_stored_face_is_skipped_not_fatal(db: Path, caplog: pytest.LogCaptureFixture) -> None:
    with FaceStore(db) as store:
        store.save_faces([LearnedFace(1, _feats(1, 2)), LearnedFace(2, _feats(2, 2))])
    raw = sqlite3.connect(db)
    raw.execute("UPDATE features SET vector = x'0000' WHERE face_id = 1 AND idx = 1")
    raw.commit()
    raw.close()
    with caplog.at_level(logging.ERROR), FaceStore(db) as store:
        assert store.recovered_from is None
        assert [f.face_id for f in store.load_faces()] == [2]
    assert any("skipping invalid stored face 1" in r.getMessage() for r in caplog.records)


def test_a_store_of_another_embedder_space_is_refused_not_mixed(db: Path) -> None:
    with FaceStore(db, embedding_space="sface_2021dec") as store:
        store.save_face(LearnedFace(1, _feats(1, 3)))
    with pytest.raises(FaceStoreError, match="space 'sface_2021dec' but this master compares 'dlib_resnet_v1'"):
        FaceStore(db)
    with FaceStore(db, embedding_space=None) as store:  # adopt the stored space (CLI)
        assert store.embedding_space == "sface_2021dec" and [f.face_id for f in store.load_faces()] == [1]


def test_a_store_from_before_spaces_is_the_dlib_space(db: Path) -> None:
    with FaceStore(db) as store:
        store.save_face(LearnedFace(1, _feats(1, 3)))
    with contextlib.closing(sqlite3.connect(db)) as conn, conn:
        conn.execute("DELETE FROM meta WHERE key = 'embedding_space'")
    with pytest.raises(FaceStoreError, match="space 'dlib_resnet_v1'"):
        FaceStore(db, embedding_space="sface_2021dec")
    with FaceStore(db) as store:
        assert store.embedding_space == "dlib_resnet_v1" and len(store.load_faces()) == 1


def test_body_pairs_an_earlier_version_stored_are_deleted_from_every_file_on_open(db: Path) -> None:
    """Earlier versions kept body pairs of an online metric update beside the faces: the first writable open
    drops them (their bytes too) and keeps the faces; a read-only open (the CLI listing) changes nothing."""
    pair = _distinctive(4321.0)[0]
    with FaceStore(db) as store:
        store.save_face(LearnedFace(1, _feats(1, 3)))
    with contextlib.closing(sqlite3.connect(db)) as conn, conn:
        conn.execute("CREATE TABLE body_pairs (face_a INTEGER, face_b INTEGER, positive INTEGER, stamp_s REAL, "
                     "vector BLOB)")
        conn.execute("INSERT INTO body_pairs VALUES (1, 1, 1, 0.0, ?)", (pair.tobytes(),))
        conn.execute("INSERT INTO meta(key, value) VALUES ('body_pairs_subspace', 'sub')")
    assert _contains_any(db, pair[None, :])  # sanity: the grep finds the stored pair
    with FaceStore(db, read_only=True) as store:
        assert len(store.load_faces()) == 1
    assert _contains_any(db, pair[None, :])
    with FaceStore(db) as store:
        assert [f.face_id for f in store.load_faces()] == [1]
        with contextlib.closing(sqlite3.connect(f"file:{db}?mode=ro", uri=True)) as raw:
            tables = {r[0] for r in raw.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
            keys = {r[0] for r in raw.execute("SELECT key FROM meta")}
        assert "body_pairs" not in tables and "body_pairs_subspace" not in keys
        assert _contains_any(db, pair[None, :]) == []


def test_cli_never_prints_raw_control_characters_and_refuses_them(db: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    import sqlite3

    _cli_store(db)
    hostile = "Ann\n     9  Mallory  1  1  x  y\x1b[2J" + "z" * 1000  # written by an older version
    conn = sqlite3.connect(db)
    with conn:
        conn.execute("UPDATE faces SET name = ? WHERE face_id = 1", (hostile,))
    conn.close()
    assert cli_main(["--db", str(db), "list"]) == 0
    out = capsys.readouterr().out
    assert "\x1b" not in out and len(out.splitlines()) == 5  # header, 3 rows, count
    assert cli_main(["--db", str(db), "rename", "2", "Eve\nroot"]) == 2
    assert "control characters" in capsys.readouterr().err
    with FaceStore(db) as store:
        with pytest.raises(ValueError, match="more than 64"):
            store.set_name(2, "x" * 1_000_000)
        assert [s.name for s in store.list_faces()][1] is None


# ------------------------------------------------------------------------------------------------ issue 12, item 5
def test_a_symlinked_path_or_a_directory_others_can_write_is_refused(tmp_path: Path) -> None:
    import os

    target = tmp_path / "elsewhere.db"
    target.write_bytes(b"")
    os.chmod(target, 0o644)
    private = tmp_path / "private"
    private.mkdir(mode=0o700)
    (private / "faces.db").symlink_to(target)
    with pytest.raises(FaceStoreError, match="symbolic link"):
        FaceStore(private / "faces.db")
    assert (target.stat().st_mode & 0o777) == 0o644  # before: followed, and its target chmodded
    shared = tmp_path / "shared"
    shared.mkdir()
    os.chmod(shared, 0o777)
    with pytest.raises(FaceStoreError, match="written by other users"):
        FaceStore(shared / "faces.db")
    assert not (shared / "faces.db").exists()


@pytest.mark.skipif(not hasattr(__import__("os"), "geteuid") or __import__("os").geteuid() != 0,
                    reason="giving a file to another user needs root")
def test_a_database_of_another_user_is_refused(db: Path) -> None:
    import os

    FaceStore(db).close()
    os.chown(db, 12345, 12345)
    with pytest.raises(FaceStoreError, match="belongs to user id 12345"):
        FaceStore(db)


def test_listing_never_moves_or_changes_a_damaged_database(db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _cli_store(db)
    data = bytearray(db.read_bytes())
    data[100:4096] = b"\xa5" * (4096 - 100)  # the schema page is garbage now
    db.write_bytes(bytes(data))
    assert cli_main(["--db", str(db), "list"]) != 0
    assert "damaged" in capsys.readouterr().err
    assert db.read_bytes() == bytes(data)  # before: moved to faces.db.corrupt-<time> and a fresh store made
    assert not [p for p in db.parent.iterdir() if "corrupt" in p.name]


def test_faces_lost_with_the_wal_are_reported_and_their_ids_never_reused(tmp_path: Path,
                                                                         caplog: pytest.LogCaptureFixture) -> None:
    import shutil

    live, crashed = tmp_path / "live", tmp_path / "crashed"
    live.mkdir(mode=0o700)
    crashed.mkdir(mode=0o700)
    store = FaceStore(live / "faces.db")
    for fid in range(1, 5):  # four faces, one commit each, all still in the WAL
        store.save_face(LearnedFace(fid, _feats(fid, 3), None, 1.0 * fid, 1.0 * fid, 3))
    for name in ("faces.db", "faces.db-wal", "faces.db.ids"):  # the files as a kill -9 leaves them
        shutil.copy(live / name, crashed / name)
    store.close()
    wal = bytearray((crashed / "faces.db-wal").read_bytes())
    cut = int(len(wal) * 0.6)
    # 64 corrupt bytes (inverted: zeroes could land on bytes already zero): SQLite drops this frame and every later
    # one, silently
    wal[cut:cut + 64] = bytes(b ^ 0xFF for b in wal[cut:cut + 64])
    (crashed / "faces.db-wal").write_bytes(bytes(wal))
    with caplog.at_level("ERROR"), FaceStore(crashed / "faces.db") as damaged:
        kept = damaged.face_ids()
        assert kept and len(kept) < 4 and damaged.lost_face_ids == [f for f in range(1, 5) if f not in kept]
        assert damaged.max_face_id() == 4  # before: the counter went back with the rows (ids reused)
    assert "FACE STORE LOST FACES" in caplog.text and str(damaged.lost_face_ids[-1]) in caplog.text
    with FaceStore(crashed / "faces.db") as reopened:  # reported once; the counter stays
        assert reopened.lost_face_ids == [] and reopened.max_face_id() == 4


def test_faces_still_readable_in_a_damaged_file_are_recovered_and_said(db: Path,
                                                                       caplog: pytest.LogCaptureFixture) -> None:
    with FaceStore(db) as store:
        store.save_faces([LearnedFace(fid, _feats(fid, 3), "Ann" if fid == 2 else None, 1.0, 2.0, 4)
                          for fid in (1, 2, 3)])
    conn = sqlite3.connect(db)
    root = conn.execute("SELECT rootpage FROM sqlite_master WHERE name = 'faces_name'").fetchone()[0]
    page = conn.execute("PRAGMA page_size").fetchone()[0]
    conn.close()
    with open(db, "r+b") as fh:  # the name index is garbage now: integrity_check fails, the tables are intact
        fh.seek((root - 1) * page)
        fh.write(b"\xa5" * page)
    with caplog.at_level(logging.ERROR), FaceStore(db) as store:
        assert store.recovered_from is not None and store.salvaged_face_ids == [1, 2, 3]
        assert [(f.face_id, f.name, f.features.shape) for f in store.load_faces()] == \
            [(1, None, (3, DIM)), (2, "Ann", (3, DIM)), (3, None, (3, DIM))]
        assert store.integrity_ok() and store.lost_face_ids == []
    assert "recovered 3 of 3 faces" in caplog.text  # before: moved aside, every face gone


@pytest.mark.parametrize("face_id", ["0", "-5", str(2**64 - 1)])
def test_cli_refuses_face_ids_out_of_range(db: Path, face_id: str, capsys: pytest.CaptureFixture[str]) -> None:
    _cli_store(db)
    for command in (["forget", face_id], ["rename", face_id, "Bea"]):
        assert cli_main(["--db", str(db), *command]) == 2
        assert "face id must be between 1 and 9223372036854775807" in capsys.readouterr().err
