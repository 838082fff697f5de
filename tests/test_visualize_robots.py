"""``sgatwalk visualize`` for the robots of example-robot-data (Unitree G1, PAL Talos).

Their links carry visual meshes (``robots.Geom(kind="mesh")``): each is logged once, static, as a
Rerun ``Asset3D`` under its link's entity with the geom's local pose, so the link transforms move it.
The viewer's forward kinematics must honour joint origins with rotations (``JointSpec.rpy``: the
G1's hip-roll, knee and shoulder joints), checked against MuJoCo. .rrd files are read back with
``rerun.chunk.RrdReader`` (rerun-sdk 0.41), as in tests/test_visualize.py.
"""

import json
import os

import mujoco
import numpy as np
import pytest

from common.spatial import quat_from_rpy
from envs import HoldPose, SimWorld, Recording, RecordingError, rollout
from experiments import viz
from experiments.cli import main
from robots import get_robot, nao_h25


# ---------------------------------------------------------------------------- helpers
def read_rrd(path):
    """{entity: {"static": {column: arrow array of the last static row}, "rows": time-varying rows,
    "temporal": {column: [arrow arrays]}}}; blobs stay arrow arrays (a G1 file holds 14 MB of meshes)."""
    from rerun.chunk import RrdReader

    store = RrdReader(os.fspath(path)).stream().collect()
    out: dict[str, dict] = {}
    for c in store.stream().to_chunks():
        e = out.setdefault(c.entity_path, {"static": {}, "rows": 0, "temporal": {}})
        b = c.to_record_batch()
        for name in b.schema.names:
            if ":" not in name:
                continue
            if c.is_static:
                e["static"][name] = b.column(name)[b.num_rows - 1]
            else:
                e["temporal"].setdefault(name, []).append(b.column(name))
        if not c.is_static:
            e["rows"] += c.num_rows
    return out


def f32(x):
    return np.asarray(x, np.float64).astype(np.float32)


def mesh_geoms(robot):
    """[(link, geom)] of every visual mesh, root first."""
    return ([(robot.root, g) for g in robot.root_geoms if g.kind == "mesh"]
            + [(j.child, g) for j in robot.joints for g in j.geoms if g.kind == "mesh"])


@pytest.fixture(scope="module")
def recs():
    """0.15 s of each robot holding its crouch in the sim."""
    out = {}
    for name in ("g1", "talos"):
        robot = get_robot(name)
        env = SimWorld(robot)
        out[name] = rollout(env, HoldPose(robot), seed=1, seconds=0.15)
        env.close()
    return out


# ---------------------------------------------------------------------------- kinematics
def test_robot_size_and_sole():
    """The camera scale and footstep boxes: exactly the NAO's constants for the NAO."""
    nao = nao_h25()
    assert viz._robot_scale(nao) == 1.0
    assert viz._sole_geometry(nao) == (viz.SOLE_BOX, viz.SOLE_CENTER)
    g1, talos = get_robot("g1"), get_robot("talos")
    assert 2.0 < viz._robot_scale(g1) < viz._robot_scale(talos) < 4.0
    box, centre = viz._sole_geometry(g1)
    sole = next(g for g in next(j for j in g1.joints if j.child == g1.frames["l_sole"].link).geoms if g.kind == "box")
    assert box[:2] == pytest.approx(sole.size[:2]) and box[2] == viz.SOLE_BOX[2]


# ---------------------------------------------------------------------------- .rrd contents
@pytest.mark.parametrize("name", ["g1", "talos"])
def test_meshes_logged_under_link_entities(recs, tmp_path, name):
    rec = recs[name]
    robot = rec.robot
    assert rec.meta["robot"] == name and robot.name == name
    path = tmp_path / f"{name}.rrd"
    viz.log_rollouts_to_rrd({"sim": rec}, path)
    data = read_rrd(path)
    T = len(rec)
    # every link moves: one transform per row, equal to the forward kinematics
    links, P, Q = viz.forward_kinematics(robot, rec.group("q"), rec.group("gt.base"), rec.group("gt.quat"))
    for i, link in enumerate(links):
        e = data[f"/sim/robot/{link}"]
        assert e["rows"] == T, link
        tr = np.concatenate([np.asarray(a.flatten().flatten()).reshape(-1, 3)
                             for a in e["temporal"]["Transform3D:translation"]])
        np.testing.assert_allclose(tr, P[:, i], atol=1e-6, err_msg=link)
    # every mesh: once, static, under its link, with the geom's local pose and the file's bytes
    geoms = mesh_geoms(robot)
    assert len(geoms) > 20
    mesh_entities = {e for e in data if "/mesh/" in e}
    assert len(mesh_entities) == len(geoms)
    seen = set()
    for link, g in geoms:  # named by file stem; a file used twice on a link (Talos's fingertips): stem_2
        stem = os.path.splitext(os.path.basename(g.mesh))[0]
        e, k = f"/sim/robot/{link}/mesh/{stem}", 2
        while e in seen:
            e, k = f"/sim/robot/{link}/mesh/{stem}_{k}", k + 1
        assert e in data, e
        seen.add(e)
        ent = data[e]
        assert ent["rows"] == 0  # static only: the link's transform moves it
        st = ent["static"]
        assert st["Asset3D:media_type"].as_py() == ["model/stl"]
        blob = np.asarray(st["Asset3D:blob"].values.flatten())
        with open(g.mesh, "rb") as f:
            assert blob.tobytes() == f.read(), e
        np.testing.assert_allclose(st["Transform3D:translation"].as_py()[0], f32(g.xyz), atol=1e-7)
        np.testing.assert_allclose(st["Transform3D:scale"].as_py()[0], f32(g.size), atol=0)
        qx = viz._xyzw(np.array(quat_from_rpy(*g.rpy)))
        q = np.array(st["Transform3D:quaternion"].as_py()[0])
        np.testing.assert_allclose(np.sign(np.dot(q, qx)) * q, qx, atol=1e-6)
    if name == "talos":  # mirrored meshes (URDF scale 1 -1 1) keep their scale
        assert any(g.size == (1.0, -1.0, 1.0) for _, g in geoms)
    # the sole boxes (collision) are drawn as primitives on the feet
    for frame in ("l_sole", "r_sole"):
        assert "Boxes3D:half_sizes" in data[f"/sim/robot/{robot.frames[frame].link}/geom"]["static"]
    # the NAO-only leg-joint plots follow the robot's own leg joints
    for j in robot.groups["legs"]:
        assert data[f"/sim/ts/joints/{j}/q"]["rows"] == T


def test_nao_has_no_meshes(tmp_path):
    robot = nao_h25()
    env = SimWorld()
    rec = rollout(env, HoldPose(robot), seed=0, seconds=0.05)
    viz.log_rollouts_to_rrd({"sim": rec}, tmp_path / "nao.rrd")
    data = read_rrd(tmp_path / "nao.rrd")
    assert not [e for e in data if "/mesh/" in e or "/geom/" in e]
    assert {e for e in data if e.endswith("/geom")} == {
        f"/sim/robot/{link}/geom" for link in (robot.root, *(j.child for j in robot.joints if j.geoms))}


# ---------------------------------------------------------------------------- refusals
def test_robot_mismatch_and_mixed_robots_are_refused(recs, tmp_path):
    g1 = recs["g1"]
    nao_cols = Recording(dict(g1.columns), dict(g1.meta, robot="nao"))  # G1 columns labelled NAO
    with pytest.raises(RecordingError, match="recording is of robot 'nao' but has none of its joint"):
        viz.log_rollouts_to_rrd({"sim": nao_cols}, tmp_path / "x.rrd")
    with pytest.raises(RecordingError, match="robot 'atlas'"):
        viz.log_rollouts_to_rrd({"sim": Recording(dict(g1.columns), dict(g1.meta, robot="atlas"))}, tmp_path / "x.rrd")
    with pytest.raises(ValueError, match="different robots"):
        viz.log_rollouts_to_rrd({"g1": g1, "talos": recs["talos"]}, tmp_path / "x.rrd")
    assert not os.path.exists(tmp_path / "x.rrd")


@pytest.mark.parametrize("argv,msg", [
    (["g1.parquet", "--robot", "g1"], "--robot is for a live rollout"),
    (["--robot", "g1", "--world", "grounded"], "world 'grounded' is the NAO's only"),
    (["--robot", "talos", "--pose", "deep_crouch"], "unknown pose 'deep_crouch' for --robot talos"),
    (["--robot", "asimo"], "argument --robot: invalid choice"),
])
def test_cli_robot_option_errors(recs, tmp_path, capsys, monkeypatch, argv, msg):
    monkeypatch.chdir(tmp_path)
    recs["g1"].to_parquet(tmp_path / "g1.parquet")
    assert main(["visualize", *argv]) == 2
    err = capsys.readouterr().err
    assert msg in err and "Traceback" not in err
    assert not os.path.exists(tmp_path / "sgatwalk.rrd")


# ---------------------------------------------------------------------------- the command
def test_cli_recording_of_g1(recs, tmp_path, capsys):
    """With recordings as input the robot comes from the metadata."""
    src = recs["g1"].to_parquet(tmp_path / "g1.parquet")
    out = tmp_path / "g1.rrd"
    assert main(["visualize", src, "--save", os.fspath(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert [r["label"] for r in res["recordings"]] == ["sim"]
    data = read_rrd(out)
    assert "/sim/robot/pelvis/mesh/pelvis" in data


def test_cli_live_walk_of_g1(tmp_path, capsys, monkeypatch):
    """``--robot g1``: the G1's gait parameters (walk_engine.params_for) in the G1 world."""
    from walk_engine import params_for

    monkeypatch.chdir(tmp_path)
    assert main(["visualize", "--robot", "g1", "--world", "sim", "--seconds", "0.3", "--record", "rec.parquet",
                 "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["path"] == "sgatwalk.rrd" and res["recordings"][0]["rows"] == 30
    rec = Recording.from_parquet(tmp_path / "rec.parquet")
    g1 = get_robot("g1")
    assert rec.meta["robot"] == "g1" and rec.meta["params"] == params_for(g1).initial().to_dict()
    assert rec.meta["footsteps"] and "plan.com.x" in rec.columns
    data = read_rrd(tmp_path / "sgatwalk.rrd")
    assert len({e for e in data if "/mesh/" in e}) == len(mesh_geoms(g1))
    assert data["/sim/plan/com"]["rows"] == 30
    # footsteps drawn with the G1's sole box
    half = data["/sim/plan/footsteps"]["static"]["Boxes3D:half_sizes"].as_py()
    box, _ = viz._sole_geometry(g1)
    np.testing.assert_allclose(half[0], f32(np.asarray(box) / 2), atol=1e-7)
