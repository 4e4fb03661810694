"""The camera map: fusion rules over the cameras' floor summaries, and nav2 map files (save, load, corrupt files)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from face_reid_camera.common.floor_snapshot import FloorOccupancySnapshot
from face_reid_master.robot.camera_map import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    CameraMapConfig,
    CameraMapFusion,
    OccupancyGridMap,
    fuse_snapshots,
    load_nav2_map,
    save_nav2_map,
)

R = 0.05


def _snap(camera: str, floor: list[list[int]], band: list[list[int]], col0: int = 0, row0: int = 0,
          stamp: float = 1.0, resolution: float = R) -> FloorOccupancySnapshot:
    return FloorOccupancySnapshot(camera, stamp, resolution, col0 * resolution, row0 * resolution, 0.1, 0.3, 1,
                                  np.array(floor), np.array(band))


def test_fusion_rules_per_cell() -> None:
    # one row of cells: (floor, band) counts
    cells = [(2, 5), (50, 5), (0, 2), (3, 0), (0, 0), (10, 4), (7, 3)]
    snap = _snap("a", [[f for f, _ in cells]], [[o for _, o in cells]])
    grid = fuse_snapshots([snap], CameraMapConfig())
    # band >= 3 and >= 30% of the cell's points: occupied; else floor >= 3: free; else unknown
    assert grid.data.tolist() == [[OCCUPIED, FREE, UNKNOWN, FREE, UNKNOWN, FREE, OCCUPIED]]
    strict = fuse_snapshots([snap], CameraMapConfig(min_occupied_points=6, min_free_points=20))
    assert strict.data.tolist() == [[UNKNOWN, FREE, UNKNOWN, UNKNOWN, UNKNOWN, UNKNOWN, UNKNOWN]]


def test_cameras_are_summed_at_their_world_cells() -> None:
    a = _snap("a", [[0, 0]], [[2, 0]], col0=10, row0=-4)   # cells x 0.50-0.60, y -0.20
    b = _snap("b", [[0], [9]], [[2], [0]], col0=10, row0=-4)  # cell x 0.50 (two rows)
    c = _snap("c", [[20]], [[0]], col0=-3, row0=2)          # far away: the grid spans both
    grid = fuse_snapshots([a, b, c], CameraMapConfig())
    assert (grid.origin_x_m, grid.origin_y_m) == pytest.approx((-0.15, -0.2))
    assert grid.width == 15 and grid.height == 7
    # a and b each saw 2 band points in the cell at (0.525, -0.175): 4 together, occupied
    assert grid.value_at(np.array([[0.525, -0.175], [0.575, -0.175], [0.525, -0.125], [-0.125, 0.125],
                                   [0.0, 0.0]])).tolist() == [OCCUPIED, UNKNOWN, FREE, FREE, UNKNOWN]
    alone = fuse_snapshots([a], CameraMapConfig())
    assert alone.value_at(np.array([0.525, -0.175])).tolist() == [UNKNOWN]


def test_latest_summary_per_camera_and_one_resolution() -> None:
    fusion = CameraMapFusion()
    assert fusion.grid() is None
    assert fusion.update(_snap("a", [[9]], [[0]], stamp=5.0))
    assert not fusion.update(_snap("a", [[0]], [[9]], stamp=4.0))  # older: ignored
    assert fusion.grid().data.tolist() == [[FREE]]
    assert fusion.update(_snap("a", [[0]], [[9]], stamp=6.0))
    assert fusion.grid().data.tolist() == [[OCCUPIED]]
    fusion.update(_snap("b", [[9]], [[0]], col0=1))
    assert fusion.cameras == ["a", "b"] and fusion.grid().data.tolist() == [[OCCUPIED, FREE]]
    with pytest.raises(ValueError, match="resolution_m"):
        fusion.update(_snap("c", [[9]], [[0]], resolution=0.1))
    with pytest.raises(ValueError, match="resolution_m"):
        fuse_snapshots([_snap("a", [[1]], [[0]]), _snap("c", [[1]], [[0]], resolution=0.1)], CameraMapConfig())
    with pytest.raises(ValueError, match="max_cells"):
        fuse_snapshots([_snap("a", [[1]], [[0]]), _snap("c", [[1]], [[0]], col0=5000, row0=5000)],
                       CameraMapConfig(max_cells=1000))


def test_a_flood_of_camera_ids_is_bounded_and_not_echoed_whole() -> None:
    fusion = CameraMapFusion(CameraMapConfig(max_cameras=3))
    for cam in ("a", "b", "c"):
        fusion.update(_snap(cam, [[9]], [[0]]))
    with pytest.raises(ValueError, match="max_cameras") as refused:
        fusion.update(_snap("x" * 100_000, [[9]], [[0]]))
    assert len(str(refused.value)) < 200 and fusion.cameras == ["a", "b", "c"]
    assert fusion.update(_snap("a", [[0]], [[9]], stamp=2.0))  # a known camera still updates


def _grid() -> OccupancyGridMap:
    rng = np.random.default_rng(0)
    data = rng.choice(np.array([UNKNOWN, FREE, OCCUPIED], dtype=np.int8), size=(37, 52))
    return OccupancyGridMap(data, 0.05, -1.25, 2.4, 0.0)


def test_save_load_round_trip_is_a_nav2_map(tmp_path: Path) -> None:
    grid = _grid()
    ypath, ipath = save_nav2_map(grid, tmp_path / "maps" / "camera_map.yaml")
    assert ipath == tmp_path / "maps" / "camera_map.pgm"
    doc = yaml.safe_load(ypath.read_text())
    assert doc == {"image": "camera_map.pgm", "mode": "trinary", "resolution": 0.05, "origin": [-1.25, 2.4, 0.0],
                   "negate": 0, "occupied_thresh": 0.65, "free_thresh": 0.196}
    raw = ipath.read_bytes()
    assert raw.startswith(b"P5\n") and b"\n52 37\n255\n" in raw and len(raw.split(b"255\n", 1)[1]) == 52 * 37
    pixels = cv2.imread(str(ipath), cv2.IMREAD_UNCHANGED)  # an independent PGM reader
    assert pixels.shape == (37, 52)
    # nav2 conventions: top image row = the grid's last row; occupied black, free 254, unknown 205
    assert np.array_equal(pixels[::-1] == 0, grid.data == OCCUPIED)
    assert np.array_equal(pixels[::-1] == 254, grid.data == FREE)
    assert np.array_equal(pixels[::-1] == 205, grid.data == UNKNOWN)
    back = load_nav2_map(ypath)
    assert np.array_equal(back.data, grid.data)
    assert (back.resolution_m, back.origin_x_m, back.origin_y_m, back.origin_yaw_rad) == (0.05, -1.25, 2.4, 0.0)
    assert back.frame == "map"


def test_load_follows_nav2_thresholds_negate_and_formats(tmp_path: Path) -> None:
    grid = _grid()
    ypath, ipath = save_nav2_map(grid, tmp_path / "m")
    assert ypath.name == "m.yaml"
    doc = yaml.safe_load(ypath.read_text())
    # nav2's map_saver default free_thresh 0.25 turns grey 205 into free space: what nav2 does, we do
    ypath.write_text(yaml.safe_dump({**doc, "free_thresh": 0.25}))
    assert np.array_equal(load_nav2_map(ypath).data == FREE, grid.data != OCCUPIED)
    # negate: black is free, white and grey (occ = shade 0.8 > 0.65) occupied
    ypath.write_text(yaml.safe_dump({**doc, "negate": 1}))
    negated = load_nav2_map(ypath).data
    assert np.array_equal(negated == FREE, grid.data == OCCUPIED) and np.all(negated[grid.data != OCCUPIED] == 100)
    # P2 (ASCII) PGM with comments, maxval 1000, in a sub-directory, relative path
    pixels = cv2.imread(str(ipath), cv2.IMREAD_UNCHANGED).astype(int) * 1000 // 255
    (tmp_path / "img").mkdir()
    body = "\n".join(" ".join(str(v) for v in row) for row in pixels)
    (tmp_path / "img" / "a.pgm").write_text(f"P2\n# a comment\n52 37\n# another\n1000\n{body}\n")
    ypath.write_text(yaml.safe_dump({**doc, "image": "img/a.pgm"}))
    assert np.array_equal(load_nav2_map(ypath).data, grid.data)
    # PNG (grey and colour with an opaque alpha channel) through cv2
    cv2.imwrite(str(tmp_path / "a.png"), cv2.imread(str(ipath), cv2.IMREAD_UNCHANGED))
    ypath.write_text(yaml.safe_dump({**doc, "image": "a.png"}))
    assert np.array_equal(load_nav2_map(ypath).data, grid.data)
    grey = cv2.imread(str(ipath), cv2.IMREAD_UNCHANGED)
    cv2.imwrite(str(tmp_path / "b.png"), cv2.merge([grey, grey, grey]))
    ypath.write_text(yaml.safe_dump({**doc, "image": "b.png"}))
    assert np.array_equal(load_nav2_map(ypath).data, grid.data)
    # nav2 averages an opaque alpha channel in with the colour in trinary mode: grey 205 becomes free
    cv2.imwrite(str(tmp_path / "c.png"), cv2.merge([grey, grey, grey, np.full_like(grey, 255)]))
    ypath.write_text(yaml.safe_dump({**doc, "image": "c.png"}))
    assert np.array_equal(load_nav2_map(ypath).data == FREE, grid.data != OCCUPIED)


@pytest.mark.parametrize("yaml_text,image,match", [
    ("image: m.pgm\nresolution: 0.05\n", None, "missing origin"),
    ("image: m.pgm\nresolution: fast\norigin: [0, 0, 0]\n", None, "must be numbers"),
    ("image: m.pgm\nresolution: -1\norigin: [0, 0, 0]\n", None, "resolution"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0]\n", None, "origin"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nmode: fancy\n", None, "mode"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nfree_thresh: 0.9\n", None, "free_thresh"),
    ("image: gone.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", None, "gone.pgm"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", b"P5\n4 4\n255\n\x00\x00", "cut short"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", b"P6\n4 4\n255\n" + bytes(48), "not a PGM"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", b"P5\nfour 4\n255\n" + bytes(16), "non-numeric"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", b"P2\n2 2\n255\n1 2 3\n", "3 pixel values"),
    ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", b"P2\n2 2\n100\n1 2 3 200\n", "maxval"),
    ("image: m.png\nresolution: 0.05\norigin: [0, 0, 0]\n", b"not a png", "cannot read"),
    ("- just\n- a list\n", None, "mapping"),
    ("image: [unclosed\n", None, "cannot read the map YAML"),
])
def test_corrupt_map_files_are_refused_with_a_reason(tmp_path: Path, yaml_text: str, image: bytes | None,
                                                     match: str) -> None:
    (tmp_path / "m.pgm").write_bytes(b"P5\n2 2\n255\n\x00\xfe\xcd\x00")
    if image is not None:
        name = "m.png" if "m.png" in yaml_text else "m.pgm"
        (tmp_path / name).write_bytes(image)
    (tmp_path / "m.yaml").write_text(yaml_text)
    with pytest.raises(ValueError, match=match):
        load_nav2_map(tmp_path / "m.yaml")


def test_grid_record_checks_and_geometry() -> None:
    with pytest.raises(ValueError, match="data"):
        OccupancyGridMap(np.zeros((0, 3)), 0.05)
    with pytest.raises(ValueError, match="resolution_m"):
        OccupancyGridMap(np.zeros((2, 3)), 0.0)
    with pytest.raises(ValueError, match="data values"):
        OccupancyGridMap(np.full((2, 3), 101), 0.05)
    data = np.zeros((2, 3), dtype=np.int8)
    data[1, 2] = OCCUPIED
    # a grid turned by 90 deg about its origin (1, 1): cell (row 1, col 2) centre at grid (0.25, 0.15) m
    grid = OccupancyGridMap(data, 0.1, 1.0, 1.0, np.pi / 2)
    assert grid.cell_centres() == pytest.approx(np.array([[1.0 - 0.15, 1.0 + 0.25]]))
    assert grid.value_at(grid.cell_centres()).tolist() == [OCCUPIED]
    assert grid.value_at(np.array([[1.05, 1.05], [5.0, 5.0]])).tolist() == [UNKNOWN, UNKNOWN]
