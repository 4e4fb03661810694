"""People named at run time (``face-reid-faces add``) kept in the face store: stored with their embeddings, listed,
named again after a restart, removed by ``forget`` for good; and ``face-reid-faces list`` beside a running master
(a store held open for writing by another process)."""

from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import FACES_DIR, REPO_ROOT

from face_reid_master.core import MasterConfig, MasterCore
from face_reid_master.identity.records import LearnedFace
from face_reid_master.storage.errors import FaceStoreError, FaceStoreLockedError
from face_reid_master.storage.face_store import FaceStore
from face_reid_master.tools.faces_cli import build_parser
from face_reid_master.tools.faces_cli import main as cli_main

DIM = 128


def _unit_rows(seed: int, k: int) -> np.ndarray:
    rows = np.random.default_rng(seed).normal(size=(k, DIM)).astype(np.float32)
    return rows / np.linalg.norm(rows, axis=1, keepdims=True)


@pytest.fixture
def db(tmp_path: Path) -> Path:
    return tmp_path / "store" / "faces.db"


def test_a_person_added_at_run_time_is_kept_listed_named_after_a_restart_and_forgotten(
        db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from face_reid_master.identity.predefined_people import with_kept_people

    carol = _unit_rows(3, 2)
    folder = {"Dan": _unit_rows(4, 1), "Carol": _unit_rows(5, 1)}  # the gallery folder also has a Carol
    with FaceStore(db) as store:  # the running master: add Carol
        assert store.save_person("Carol", carol, added_s=1_700_000_000.0) == 2
        store.save_face(LearnedFace(1, _unit_rows(6, 3), "Carol", 1.0, 2.0, 3))
    assert cli_main(["--db", str(db), "list"]) == 0  # before: 0 people anywhere
    out = capsys.readouterr().out
    assert "1 face(s)" in out and "1 person(s) named at run time" in out
    assert any(line.split()[:2] == ["Carol", "2"] for line in out.splitlines())
    assert cli_main(["--db", str(db), "list", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert rows[0]["face_id"] == 1 and rows[1] == {"person": "Carol", "n_embeddings": 2, "added_s": 1_700_000_000.0}
    assert all("vector" not in r and "embeddings" not in r for r in rows)
    with FaceStore(db) as store:  # a restart: the master names her again, with the embeddings added
        kept = store.load_people()
        assert list(kept) == ["Carol"] and np.array_equal(kept["Carol"], carol)
        people, both = with_kept_people(folder, kept)
        assert both == ["Carol"] and people["Carol"] is kept["Carol"] and people["Dan"] is folder["Dan"]
        core = MasterCore(MasterConfig(embedding_space="dlib_resnet_v1", body_appearance_tracking=False),
                          store=store, gallery=people)
        assert core.people.names() == ["Carol", "Dan"] and core.people.n_embeddings("Carol") == 2
    assert cli_main(["--db", str(db), "forget", "--name", "Carol"]) == 0
    assert "removed the person 'Carol' named at run time" in capsys.readouterr().out
    assert cli_main(["--db", str(db), "forget", "--name", "Carol"]) == 1  # gone: faces and person
    with FaceStore(db) as store:
        assert store.load_people() == {} and store.list_people() == [] and store.face_ids() == []
        assert not store.forget_person("Carol")
    raw = b"".join(Path(str(db) + s).read_bytes() for s in ("", "-wal") if Path(str(db) + s).exists())
    assert not any(r.astype("<f4").tobytes() in raw for r in carol)  # the embeddings are gone from the files


def test_a_store_of_the_earlier_version_gains_the_people_tables_and_lists_none(db: Path) -> None:
    with FaceStore(db) as store:
        store.save_face(LearnedFace(1, _unit_rows(1, 2)))
    conn = sqlite3.connect(db)  # as the earlier version wrote it: no people tables
    conn.executescript("DROP TABLE person_features; DROP TABLE people;")
    conn.close()
    with FaceStore(db, read_only=True) as reader:  # read-only: nothing is created, nothing listed
        assert reader.list_people() == [] and reader.load_people() == {} and reader.face_ids() == [1]
    with FaceStore(db) as store:
        assert store.save_person("Ann", _unit_rows(2, 1)) == 1 and list(store.load_people()) == ["Ann"]


def test_bad_people_are_refused(db: Path) -> None:
    with FaceStore(db) as store:
        for name, rows, said in (("", _unit_rows(1, 1), "empty"), ("Ann\n", _unit_rows(1, 1), "control"),
                                 ("Ann", _unit_rows(1, 1)[:, :64], "shape"), ("Ann", np.full((1, DIM), np.nan),
                                                                              "finite")):
            with pytest.raises(ValueError, match=said):
                store.save_person(name, rows)
        assert store.list_people() == []
    with FaceStore(db, read_only=True) as reader, pytest.raises(FaceStoreError, match="read-only"):
        reader.save_person("Ann", _unit_rows(1, 1))


_WRITER = textwrap.dedent("""
    import sys, time
    import numpy as np
    from face_reid_master.identity.records import LearnedFace
    from face_reid_master.storage.face_store import FaceStore
    store = FaceStore(sys.argv[1])
    store.save_face(LearnedFace(1, np.ones((2, 128), np.float32), "Ann", 1.0, 2.0, 3))
    if hasattr(store, "save_person"):  # (so that the test says what fails on a store without people)
        store.save_person("Carol", np.ones((1, 128), np.float32))
    print("open", flush=True)
    n = 1
    for line in sys.stdin:  # each line: save one more face (the master goes on writing)
        n += 1
        store.save_face(LearnedFace(n, np.full((2, 128), n, np.float32), None, 1.0, 2.0, 1))
        print(f"saved {n}", flush=True)
    store.close()
""")


def test_list_works_beside_a_process_holding_the_store_for_writing(db: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """The master holds the store open for writing; ``face-reid-faces list`` on that PC reads it (before: exit 3,
    "in use"), its writes go on meanwhile, and a master can start while a listing holds the file open."""
    db.parent.mkdir(mode=0o700)
    writer = subprocess.Popen([sys.executable, "-c", _WRITER, str(db)], cwd=REPO_ROOT, stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert writer.stdout is not None and writer.stdin is not None
        assert writer.stdout.readline().strip() == "open"
        assert cli_main(["--db", str(db), "list"]) == 0
        out = capsys.readouterr().out
        assert "1 face(s)" in out and "1 person(s) named at run time" in out
        with FaceStore(db, read_only=True) as reader:  # a listing still open: the writer is never blocked
            for n in (2, 3):
                writer.stdin.write("save\n")
                writer.stdin.flush()
                assert writer.stdout.readline().strip() == f"saved {n}"
            assert reader.face_ids() == [1, 2, 3]
        assert cli_main(["--db", str(db), "forget", "1"]) == 3  # an edit still waits for the master to stop
        assert "stop the master node first" in capsys.readouterr().err
        writer.stdin.close()
        assert writer.wait(timeout=60) == 0
    finally:
        if writer.poll() is None:
            writer.kill()
            writer.wait()
    with FaceStore(db, read_only=True) as reader:  # a writer may open while a reader is open (a master start)
        with FaceStore(db) as store:
            assert store.face_ids() == [1, 2, 3] and reader.list_people()[0].name == "Carol"


def test_options_are_taken_after_the_command_too() -> None:
    parser = build_parser()
    args = parser.parse_args(["--master", "X", "list", "--timeout-s", "8"])  # before: "unrecognized arguments"
    assert (args.master, args.timeout_s, args.command) == ("X", 8.0, "list")
    args = parser.parse_args(["--timeout-s", "3", "--master", "X", "forget", "--name", "A", "--key", "k"])
    assert (args.master, args.timeout_s, args.key, args.name) == ("X", 3.0, "k", "A")
    assert parser.parse_args(["list", "--db", "/tmp/f.db"]).db == Path("/tmp/f.db")
    assert parser.parse_args(["--db", "/tmp/g.db", "list"]).db == Path("/tmp/g.db")


def test_store_errors_are_said_as_sentences(db: Path) -> None:
    """A master that cannot open its store says why, without the class name in front (before:
    ``FaceStoreLockedError: face store ... is in use``): its errors are OSErrors, which the nodes say plainly."""
    from face_reid_master.storage.errors import reason_of

    with FaceStore(db):
        with pytest.raises(FaceStoreLockedError) as caught:
            FaceStore(db)
    assert isinstance(caught.value, OSError) and reason_of(caught.value).startswith(f"face store {db}")
    assert reason_of(RuntimeError("x")) == "RuntimeError: x"


def test_people_still_readable_in_a_damaged_file_are_recovered(db: Path) -> None:
    carol = _unit_rows(8, 2)
    with FaceStore(db) as store:
        store.save_face(LearnedFace(1, _unit_rows(9, 3), "Carol", 1.0, 2.0, 4))
        store.save_person("Carol", carol, added_s=5.0)
    conn = sqlite3.connect(db)
    root = conn.execute("SELECT rootpage FROM sqlite_master WHERE name = 'faces_name'").fetchone()[0]
    page = conn.execute("PRAGMA page_size").fetchone()[0]
    conn.close()
    with open(db, "r+b") as fh:  # the name index is garbage now: integrity_check fails, the tables are intact
        fh.seek((root - 1) * page)
        fh.write(b"\xa5" * page)
    with FaceStore(db) as store:  # moved aside, a fresh store: Carol is read back from the damaged file
        assert store.recovered_from is not None and store.salvaged_face_ids == [1]
        assert [(p.name, p.n_embeddings, p.added_s) for p in store.list_people()] == [("Carol", 2, 5.0)]
        assert np.array_equal(store.load_people()["Carol"], carol)


def test_add_on_the_store_with_the_master_stopped(db: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``face-reid-faces add NAME PHOTO...`` without --master: the photos' embeddings kept in the store (before:
    refused, "add works on a running master"); refused while a master holds the store."""
    photos = [str(p) for p in sorted((FACES_DIR / "deepface_id01").glob("*.jpg"))[:2]]
    with FaceStore(db):  # a running master holds it
        assert cli_main(["--db", str(db), "add", "Eve", *photos]) == 3
        assert "stop the master node first, or give --master NODE" in capsys.readouterr().err
    assert cli_main(["add", "Eve", *photos, str(db.parent / "missing.jpg"), "--db", str(db)]) == 0
    captured = capsys.readouterr()
    assert "added 'Eve' with 2 embeddings" in captured.out and "missing.jpg" in captured.err
    with FaceStore(db, read_only=True) as store:
        assert store.load_people()["Eve"].shape == (2, DIM)
    assert cli_main(["--db", str(db), "add", "Eve\x1b[2J", *photos]) == 2  # a name the master would refuse
    assert cli_main(["--db", str(db), "forget", "--name", "Eve"]) == 0
