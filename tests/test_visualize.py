"""``sgatwalk visualize`` and experiments.viz: .rrd files read back without a viewer.

Each written file is read with ``rerun.chunk.RrdReader`` (rerun-sdk 0.41, Python API reference
https://ref.rerun.io/docs/python/) and
compared with the recording it came from: entity paths, time points per entity, sample values.
"""

import json
import math
import os

import mujoco
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from envs import HoldPose, RealWorld, SimWorld, Recording, RecordingError, rollout
from experiments import viz
from experiments.cli import main
from robots import get_robot, nao_h25


# ---------------------------------------------------------------------------- helpers
def read_rrd(path):
    """{entity: {"static": {column: value}, "rows": n, "time": s (n,), "step": (n,), column: [row values]}}."""
    from rerun.chunk import RrdReader

    store = RrdReader(os.fspath(path)).stream().collect()
    out: dict[str, dict] = {}
    for c in store.stream().to_chunks():
        e = out.setdefault(c.entity_path, {"static": {}, "rows": 0, "_batches": []})
        b = c.to_record_batch()
        if c.is_static:
            for name in b.schema.names:
                if ":" in name:
                    e["static"][name] = b.column(name).to_pylist()[-1]
        else:
            e["rows"] += c.num_rows
            e["_batches"].append(b)
    for e in out.values():
        batches = e.pop("_batches")
        if not batches:
            continue
        cols: dict[str, list] = {}
        for b in batches:
            for name in b.schema.names:
                if name == "rerun.controls.RowId":
                    continue
                vals = b.column(name)
                if name == "time":
                    vals = vals.cast(pa.int64()).to_numpy() / 1e9
                    cols.setdefault(name, []).extend(vals.tolist())
                else:
                    cols.setdefault(name, []).extend(vals.to_pylist())
        order = np.argsort(cols["time"], kind="stable")
        for name, vals in cols.items():
            e[name] = [vals[i] for i in order]
        e["time"] = np.asarray(e["time"])
        if "step" in e:
            e["step"] = np.asarray(e["step"])
    return out


def scalars(entity):
    return np.array([row[0] for row in entity["Scalars:scalars"]])


def xyzw(q_wxyz):
    return np.concatenate([q_wxyz[..., 1:], q_wxyz[..., :1]], axis=-1)


@pytest.fixture(scope="module")
def recs():
    """A short sim and real rollout holding the crouch (real on its lumpy field, seed 3), the sim
    one with a synthetic plan and footsteps, and a synthetic fall."""
    robot = nao_h25()
    sim_env = SimWorld()
    sim = rollout(sim_env, HoldPose(robot), seed=3, seconds=0.5)
    real_env = RealWorld()
    real = rollout(real_env, HoldPose(robot), seed=3, seconds=0.4)
    real_terrain = real_env.terrain
    real_env.close()
    n = len(sim)
    cols = dict(sim.columns)
    cols["plan.com.x"] = np.linspace(0.0, 0.05, n)
    cols["plan.com.y"] = 0.01 * np.sin(np.arange(n))
    cols["plan.com.z"] = np.full(n, 0.255)
    cols["plan.zmp.x"] = np.linspace(0.01, 0.06, n)
    cols["plan.zmp.y"] = np.where(np.arange(n) < n // 2, 0.05, -0.05)
    meta = dict(sim.meta, fell=True, fall_time=float(sim.t[-1] + sim.meta["control_dt"]), fall_reason="tilt",
                footsteps=[{"x": 0.0, "y": 0.05, "yaw": 0.0, "side": "L", "t_start": 0.0, "t_end": 0.3},
                           {"x": 0.0, "y": -0.05, "yaw": 0.1, "side": "R", "t_start": 0.0, "t_end": None},
                           {"x": 0.04, "y": 0.05, "yaw": 0.0, "side": "L", "t_start": 0.4, "t_end": None}])
    planned = Recording(cols, meta)
    planned.validate()
    return {"sim": sim, "real": real, "planned": planned, "real_terrain": real_terrain}


# ---------------------------------------------------------------------------- kinematics and terrain
@pytest.mark.parametrize("name,atol", [
    ("nao", 1e-9),
    ("g1", 1e-9),  # joint origins with rotations (rpy)
    # Talos: the URDF both engines load writes gripper_right_joint's rpy yaw -3.14159265358 with 9
    # significant digits (-3.14159265, robots.nao._fmt), 3.6e-9 rad off the spec: 1.8e-9 in MuJoCo's
    # quaternion of that link; every other link agrees to 1e-15.
    ("talos", 5e-9),
])
def test_forward_kinematics_matches_mujoco(name, atol):
    robot = get_robot(name)
    env = SimWorld(robot)
    m, d = env.model, env.data
    rng = np.random.default_rng(0)
    T, n = 5, len(robot.joint_names)
    q = rng.uniform(robot.lower, robot.upper, (T, n))
    pos = rng.normal(0, 0.3, (T, 3))
    quat = rng.normal(size=(T, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    links, P, Q = viz.forward_kinematics(robot, q, pos, quat)
    assert links[0] == robot.root and P.shape == (T, n + 1, 3) and Q.shape == (T, n + 1, 4)
    for k in range(T):
        d.qpos[:3], d.qpos[3:7] = pos[k], quat[k]
        d.qpos[env._qadr] = q[k]
        mujoco.mj_kinematics(m, d)
        for i, link in enumerate(links):
            b = m.body(link).id
            np.testing.assert_allclose(P[k, i], d.xpos[b], atol=1e-9, rtol=0, err_msg=link)
            sign = np.sign(np.dot(Q[k, i], d.xquat[b]))  # q and -q are one rotation
            np.testing.assert_allclose(sign * Q[k, i], d.xquat[b], atol=atol, rtol=0, err_msg=link)
    env.close()


def test_terrain_mesh_uses_mujoco_diagonal():
    from terrain import lumpy

    hf = lumpy(1, amplitude=0.02, size=(1.0, 0.6), cell_size=0.05)
    mesh = viz.terrain_mesh(hf)
    V, F = mesh["vertex_positions"], mesh["triangle_indices"]
    ny, nx = hf.shape
    assert V.shape == (ny * nx, 3) and F.shape == (2 * (ny - 1) * (nx - 1), 3)
    # the centroid of every triangle lies on the engine's surface (wrong diagonal: off by ~mm)
    c = V[F].mean(axis=1)
    np.testing.assert_allclose(c[:, 2], hf.height_at(c[:, 0], c[:, 1]), atol=1e-12)
    assert np.allclose(np.linalg.norm(mesh["vertex_normals"], axis=1), 1.0)
    flat = viz.terrain_mesh(None)
    assert flat["vertex_positions"].shape == (4, 3) and np.all(flat["vertex_positions"][:, 2] == 0)


def test_terrain_rebuilt_from_recorded_spec(recs, tmp_path):
    real = recs["real"]
    spec = real.meta["terrain"]["spec"]
    assert spec["generator"] == "lumpy" and spec["seed"] == {"entropy": 3, "spawn_key": [1]}
    back = Recording.from_parquet(real.to_parquet(tmp_path / "real.parquet"))  # the metadata is all it takes
    hf, note = viz.terrain_for(back)
    assert "recorded generator spec" in note
    np.testing.assert_array_equal(hf.heights, recs["real_terrain"].heights)  # the field the episode ran on
    assert viz.terrain_for(recs["sim"]) == (None, "flat ground (plane at z = 0)")
    # the spec decides, not the seed: another seed in the metadata does not change the field
    hf, _ = viz.terrain_for(Recording(dict(real.columns), dict(real.meta, seed=4)))
    np.testing.assert_array_equal(hf.heights, recs["real_terrain"].heights)
    # a spec that does not give the recorded field, and one that is not a spec: a flat stand-in
    for bad_spec in (dict(spec, amplitude=spec["amplitude"] / 2), dict(spec, generator="moon"), "lumpy"):
        bad = Recording(dict(real.columns), dict(real.meta, terrain=dict(real.meta["terrain"], spec=bad_spec)))
        hf, note = viz.terrain_for(bad)
        assert hf is None and "could not be regenerated" in note and "stands in" in note


def test_terrain_regenerated_from_real_recording_without_spec(recs):
    """Recordings made before specs were recorded: the real world's field is regenerated from the seed."""
    real = recs["real"]
    old = Recording(dict(real.columns), dict(real.meta, terrain={k: v for k, v in real.meta["terrain"].items()
                                                                 if k != "spec"}))
    hf, note = viz.terrain_for(old)
    assert "episode seed" in note
    np.testing.assert_array_equal(hf.heights, recs["real_terrain"].heights)
    bad = Recording(dict(old.columns), dict(old.meta, seed=4))  # metadata no longer matches
    hf, note = viz.terrain_for(bad)
    assert hf is None and "could not be regenerated" in note


def test_footsteps_from_engine_phases():
    phases = [
        {"kind": "stand", "t0": 0.0, "t1": 0.25, "support": "", "feet": {"L": [0, 0.05, 0], "R": [0, -0.05, 0]}},
        {"kind": "start", "t0": 0.25, "t1": 0.4, "support": "L", "feet": {"L": [0, 0.05, 0], "R": [0, -0.05, 0]}},
        {"kind": "ss", "t0": 0.4, "t1": 0.64, "support": "L", "feet": {"L": [0, 0.05, 0], "R": [0.02, -0.05, 0]}},
        {"kind": "ds", "t0": 0.64, "t1": 0.7, "support": "R", "feet": {"L": [0, 0.05, 0], "R": [0.02, -0.05, 0]}},
        {"kind": "ss", "t0": 0.7, "t1": 0.94, "support": "R", "feet": {"L": [0.06, 0.05, 0], "R": [0.02, -0.05, 0]}},
        {"kind": "ss", "t0": 5.0, "t1": 5.2, "support": "R", "feet": {"L": [0.5, 0.05, 0], "R": [0.02, -0.05, 0]}},
    ]
    steps = viz.footsteps_from_phases(phases, lambda x, y: (x + 1.0, y), yaw0=0.1, t_end=2.0)
    got = [(s["side"], round(s["x"], 6), s["t_start"], s["t_end"]) for s in steps]
    assert got == [("L", 1.0, 0.0, 0.7), ("R", 1.0, 0.0, 0.4), ("R", 1.02, 0.64, 2.0), ("L", 1.06, 0.94, 2.0)]
    assert all(math.isclose(s["yaw"], 0.1) for s in steps)


# ---------------------------------------------------------------------------- .rrd round trip
LEGS = nao_h25().groups["legs"]


def test_rrd_round_trip(recs, tmp_path):
    path = tmp_path / "out.rrd"
    res = viz.log_rollouts_to_rrd({"sim": recs["planned"], "real": recs["real"]}, path)
    assert res["path"] == os.fspath(path) and res["bytes"] == os.path.getsize(path) > 0
    assert not [f for f in os.listdir(tmp_path) if f != "out.rrd"]  # the temporary file was renamed
    from rerun.chunk import RrdReader

    reader = RrdReader(os.fspath(path))
    assert len(reader.recordings()) == 1 and len(reader.blueprints()) == 1
    data = read_rrd(path)
    robot = nao_h25()
    for label, rec in (("sim", recs["planned"]), ("real", recs["real"])):
        T = len(rec)
        expected = {f"/{label}/robot/{link}" for link in robot.links}
        expected |= {f"/{label}/ts/joints/{j}/{k}" for j in LEGS for k in ("cmd", "app", "q")}
        expected |= {f"/{label}/ts/gyro/{a}" for a in "xyz"} | {f"/{label}/ts/angle/{a}" for a in ("roll", "pitch")}
        expected |= {f"/{label}/ts/fsr/{s}" for s in "LR"} | {f"/{label}/com", f"/{label}/cop"}
        expected |= {f"/{label}/ts/balance/{a}/{q}" for a in "xy" for q in ("com", "cop")}
        if label == "sim":
            expected |= {"/sim/plan/com", "/sim/plan/zmp", "/sim/plan/footsteps/active"}
            expected |= {f"/sim/ts/balance/{a}/{q}" for a in "xy" for q in ("plan_com", "zmp_ref")}
        temporal = {e for e, v in data.items() if v["rows"] and e.startswith(f"/{label}/")}
        assert temporal == expected | {f"/{label}/events"} | ({"/sim/fall"} if label == "sim" else set())
        assert set(res["rows"]) >= expected
        for e in expected:  # one time point per recording row, on both timelines
            assert data[e]["rows"] == T, e
            np.testing.assert_allclose(data[e]["time"], rec.t, atol=1e-9, err_msg=e)
            np.testing.assert_array_equal(data[e]["step"], np.arange(T), err_msg=e)
        for j in LEGS:
            leader = robot.mimic.get(j, j)  # RHipYawPitch is commanded through LHipYawPitch
            np.testing.assert_array_equal(scalars(data[f"/{label}/ts/joints/{j}/q"]), rec.columns[f"q.{j}"])
            np.testing.assert_array_equal(scalars(data[f"/{label}/ts/joints/{j}/cmd"]), rec.columns[f"cmd.{leader}"])
            np.testing.assert_array_equal(scalars(data[f"/{label}/ts/joints/{j}/app"]), rec.columns[f"app.{leader}"])
        np.testing.assert_array_equal(scalars(data[f"/{label}/ts/gyro/y"]), rec.columns["gyro.y"])
        np.testing.assert_array_equal(scalars(data[f"/{label}/ts/angle/pitch"]), rec.columns["angle.pitch"])
        # the torso transform is the ground-truth base pose (float32 in Rerun)
        tor = data[f"/{label}/robot/torso"]
        np.testing.assert_allclose(np.array(tor["Transform3D:translation"])[:, 0], rec.group("gt.base"), atol=1e-6)
        np.testing.assert_allclose(np.array(tor["Transform3D:quaternion"])[:, 0], xyzw(rec.group("gt.quat")), atol=1e-6)
        # a foot: its transform agrees with forward kinematics
        links, P, Q = viz.forward_kinematics(robot, rec.group("q"), rec.group("gt.base"), rec.group("gt.quat"))
        i = links.index("l_ankle")
        np.testing.assert_allclose(np.array(data[f"/{label}/robot/l_ankle"]["Transform3D:translation"])[:, 0],
                                   P[:, i], atol=1e-6)
        np.testing.assert_allclose(np.array([p[0] for p in data[f"/{label}/com"]["Points3D:positions"]]),
                                   rec.group("gt.com"), atol=1e-6)
        # CoP: one point per row with contact, an empty row without
        cop = rec.group("gt.cop")
        rows = data[f"/{label}/cop"]["Points3D:positions"]
        assert [len(r) for r in rows] == list(np.isfinite(cop).all(1).astype(int))
        # geometry: static primitives in the link frames
        assert "Boxes3D:half_sizes" in data[f"/{label}/robot/torso/geom"]["static"]
        assert "Capsules3D:lengths" in data[f"/{label}/robot/LThigh/geom"]["static"]
        assert "Ellipsoids3D:half_sizes" in data[f"/{label}/robot/Head/geom"]["static"]
        assert "Mesh3D:vertex_positions" in data[f"/{label}/terrain"]["static"]
    # terrain: flat quad for the sim, the regenerated lumpy field for the real world
    assert len(data["/sim/terrain"]["static"]["Mesh3D:vertex_positions"]) == 4
    hf = recs["real_terrain"]
    V = np.array(data["/real/terrain"]["static"]["Mesh3D:vertex_positions"])
    np.testing.assert_allclose(V[:, 2], hf.heights.ravel(), atol=1e-6)
    # plan, footsteps, fall
    sim = recs["planned"]
    pc = np.array([p[0] for p in data["/sim/plan/com"]["Points3D:positions"]])
    np.testing.assert_allclose(pc, np.column_stack([sim.columns["plan.com.x"], sim.columns["plan.com.y"],
                                                    sim.columns["plan.com.z"]]), atol=1e-6)
    np.testing.assert_array_equal(scalars(data["/sim/ts/balance/y/zmp_ref"]), sim.columns["plan.zmp.y"])
    assert len(data["/sim/plan/footsteps"]["static"]["Boxes3D:centers"]) == 3
    active = [len(r) for r in data["/sim/plan/footsteps/active"]["Boxes3D:centers"]]
    t = sim.t
    assert active == [int(tt < 0.3) + 1 + int(tt >= 0.4) for tt in t]
    fall = data["/sim/fall"]
    assert fall["rows"] == 1 and math.isclose(fall["time"][0], sim.meta["fall_time"], abs_tol=1e-9)
    assert "tilt" in fall["Points3D:labels"][0][0]
    base = sim.group("gt.base")[-1]
    np.testing.assert_allclose(fall["Points3D:positions"][0][0][:2], base[:2], atol=1e-6)
    assert "/real/fall" not in data
    events = data["/sim/events"]
    assert events["rows"] == 2 and "fell at" in events["TextLog:text"][1][0]
    assert "/legend" in data


def test_recording_without_ground_truth_or_app(recs, tmp_path):
    """A real robot's log: no gt.*, no app.*: drawn upright at the origin, soles on z = 0."""
    rec = recs["sim"]
    cols = {k: v for k, v in rec.columns.items() if not k.startswith(("gt.", "app."))}
    bare = Recording(cols, {"robot": "nao", "control_dt": 0.01})
    path = tmp_path / "bare.rrd"
    res = viz.log_rollouts_to_rrd({"robot log": bare}, path)
    assert res["labels"] == ["robot_log"]
    data = read_rrd(path)
    assert "/robot_log/ts/joints/LKneePitch/app" not in data
    assert data["/robot_log/ts/joints/LKneePitch/q"]["rows"] == len(rec)
    assert "/robot_log/com" not in data and "/robot_log/cop" in data  # CoP from FSR + sole poses
    links, P, Q, grounded = viz.link_poses(bare)
    assert not grounded
    soles = np.minimum(viz.frame_positions(bare.robot, links, P, Q, "l_sole")[:, 2],
                       viz.frame_positions(bare.robot, links, P, Q, "r_sole")[:, 2])
    np.testing.assert_allclose(soles, 0.0, atol=1e-12)
    # the FSR-based CoP of the sim recording is close to its ground truth
    cop = viz._measured_cop(Recording({k: v for k, v in rec.columns.items() if not k.startswith("gt.cop")}, rec.meta),
                            rec.robot, *viz.forward_kinematics(rec.robot, rec.group("q"), rec.group("gt.base"),
                                                               rec.group("gt.quat")))
    ok = np.isfinite(rec.group("gt.cop")).all(1)
    assert np.abs(cop[ok, :2] - rec.group("gt.cop")[ok, :2]).max() < 0.01


def test_many_recordings_of_one_world(recs, tmp_path):
    res = viz.log_rollouts_to_rrd({"gen_000/best": recs["sim"], "gen_000/worst": recs["sim"],
                                   "eval/real seed 3": recs["real"]}, tmp_path / "run.rrd")
    assert res["labels"] == ["gen_000/best", "gen_000/worst", "eval/real_seed_3"]
    data = read_rrd(tmp_path / "run.rrd")
    assert data["/gen_000/worst/robot/torso"]["rows"] == len(recs["sim"])
    assert data["/eval/real_seed_3/ts/joints/RKneePitch/q"]["rows"] == len(recs["real"])


# ---------------------------------------------------------------------------- bad input
def test_bad_recordings_are_refused(recs, tmp_path):
    sim = recs["sim"]
    other = Recording(dict(sim.columns), dict(sim.meta, robot="talos"))
    with pytest.raises(RecordingError, match="robot 'talos'"):
        viz.log_rollouts_to_rrd({"sim": other}, tmp_path / "x.rrd")
    empty = Recording({k: v[:0] for k, v in sim.columns.items()}, dict(sim.meta))
    with pytest.raises(RecordingError, match="empty"):
        viz.log_rollouts_to_rrd({"sim": empty}, tmp_path / "x.rrd")
    with pytest.raises(ValueError, match="no recordings"):
        viz.log_rollouts_to_rrd({}, tmp_path / "x.rrd")
    with pytest.raises(ValueError, match="same entity path"):
        viz.log_rollouts_to_rrd({"a b": sim, "a_b": sim}, tmp_path / "x.rrd")
    with pytest.raises(ValueError, match="prefix"):
        viz.log_rollouts_to_rrd({"a": sim, "a/b": sim}, tmp_path / "x.rrd")
    assert not os.path.exists(tmp_path / "x.rrd")


def _write_bad(tmp_path, recs):
    sim = recs["sim"]
    other = tmp_path / "other.parquet"
    Recording(dict(sim.columns), dict(sim.meta, robot="talos")).to_parquet(other)
    empty = tmp_path / "empty.parquet"
    table = Recording({k: v[:0] for k, v in sim.columns.items()}, dict(sim.meta)).to_table()
    pq.write_table(table, empty)
    return other, empty


@pytest.mark.parametrize("case,msg", [
    ("other", "recording is of robot 'talos'"),
    ("empty", "empty (0 rows)"),
    ("missing", "no such file or directory"),
])
def test_cli_bad_input_exits_2(recs, tmp_path, capsys, case, msg):
    other, empty = _write_bad(tmp_path, recs)
    path = {"other": other, "empty": empty, "missing": tmp_path / "nope.parquet"}[case]
    assert main(["visualize", os.fspath(path), "--save", os.fspath(tmp_path / "o.rrd")]) == 2
    err = capsys.readouterr().err
    assert msg in err and "Traceback" not in err
    if case != "missing":
        assert os.fspath(path) in err  # the message names the file
    assert not os.path.exists(tmp_path / "o.rrd")


@pytest.mark.parametrize("argv,msg", [
    (["--world", "grounded"], "needs --transformer"),
    (["--world", "grounded", "--transformer", "/nonexistent/model"], "argument --transformer: no such file or directory"),
    (["--world", "moon"], "unknown world 'moon'"),
    (["--world", "sim", "--seconds", "0"], "argument --seconds: must be in (0, 3600] s"),
    (["--world", "sim", "--params", "/nonexistent/theta.json"], "argument --params: no such file"),
    (["x.parquet", "--params", "theta.json"], "--params is for a live rollout"),
    (["--spawn", "--save", "a.rrd"], "not both"),
])
def test_cli_bad_options_exit_2(tmp_path, capsys, monkeypatch, argv, msg):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "x.parquet").write_bytes(b"")  # inputs exist: the checks under test come after the path checks
    (tmp_path / "theta.json").write_text("{}")
    assert main(["visualize", *argv]) == 2
    err = capsys.readouterr().err
    assert msg in err and "Traceback" not in err


# ---------------------------------------------------------------------------- the command
def test_cli_run_directory(recs, tmp_path, capsys):
    run = tmp_path / "runs" / "demo"
    recs["sim"].to_parquet(run / "gen_000" / "best.parquet")
    recs["sim"].to_parquet(run / "gen_000" / "worst.parquet")
    recs["real"].to_parquet(run / "eval" / "real_seed3.parquet")
    pq.write_table(pa.table({"gen": [0, 1], "fitness": [1.0, 2.0]}), run / "evals.parquet")  # not a recording
    out = tmp_path / "viz.rrd"
    assert main(["visualize", os.fspath(run), "--save", os.fspath(out), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert [r["label"] for r in res["recordings"]] == ["sim/gen_000/best", "sim/gen_000/worst", "real"]
    assert res["skipped"] == [os.fspath(run / "evals.parquet")] and res["path"] == os.fspath(out)
    data = read_rrd(out)
    assert data["/sim/gen_000/best/ts/joints/LKneePitch/q"]["rows"] == len(recs["sim"])
    assert data["/real/robot/r_ankle"]["rows"] == len(recs["real"])
    empty = tmp_path / "nothing"
    empty.mkdir()
    assert main(["visualize", os.fspath(empty)]) == 2
    assert "no recordings" in capsys.readouterr().err


def test_cli_live_walk(tmp_path, capsys, monkeypatch):
    pytest.importorskip("walk_engine")
    monkeypatch.chdir(tmp_path)
    assert main(["visualize", "--world", "sim", "--seconds", "0.5", "--record", "rec.parquet", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["path"] == "sgatwalk.rrd" and os.path.exists(tmp_path / "sgatwalk.rrd")
    rec = Recording.from_parquet(tmp_path / "rec.parquet")
    assert "plan.com.x" in rec.columns and rec.meta["footsteps"] and len(rec) == 50
    data = read_rrd(tmp_path / "sgatwalk.rrd")
    np.testing.assert_array_equal(scalars(data["/sim/ts/balance/x/zmp_ref"]), rec.columns["plan.zmp.x"])
    assert data["/sim/plan/com"]["rows"] == 50
    assert len(data["/sim/plan/footsteps"]["static"]["Boxes3D:centers"]) == len(rec.meta["footsteps"])
    # the planned CoM starts under the measured one (walk frame placed at the start pose)
    assert np.hypot(*(rec.group("gt.com")[0, :2] - [rec.columns["plan.com.x"][0], rec.columns["plan.com.y"][0]])) < 0.03


def test_spawn_streams_to_a_viewer(recs, monkeypatch):
    import rerun as rr

    calls = []
    monkeypatch.setattr(rr.RecordingStream, "spawn", lambda self, **kw: calls.append(kw))
    res = viz.log_rollouts_to_rrd({"sim": recs["sim"]}, spawn=True)
    assert res["path"] is None and res["bytes"] == 0 and calls and calls[0]["default_blueprint"] is not None


def test_rerun_disabled_is_a_clear_error(recs, tmp_path, monkeypatch):
    monkeypatch.setenv("RERUN", "off")
    with pytest.raises(ValueError, match="RERUN=off"):
        viz.log_rollouts_to_rrd({"sim": recs["sim"]}, tmp_path / "x.rrd")


@pytest.mark.slow
def test_screenshot_of_the_default_layout(recs, tmp_path):
    """Needs a graphics adapter (GPU or Mesa lavapipe); ~10 s."""
    path = viz.log_rollouts_to_rrd({"sim": recs["planned"], "real": recs["real"]}, tmp_path / "s.rrd")["path"]
    try:
        png = viz.screenshot_rrd(path, tmp_path / "s.png", time_s=0.2)
    except RuntimeError as exc:
        pytest.skip(f"no headless viewer here: {exc}")
    with open(png, "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"
