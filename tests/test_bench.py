"""`reassemble bench`: discovery, the metrics against the Breaking Bad reference code,
the resumable results file, failures recorded, and a 2-worker Dask LocalCluster run."""

import json
import os
import signal
import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from reassemble.bench import BenchSet, bench, discover, options_key, read_results, run_set, select, summarize
from reassemble.cli import main
from reassemble.config import Config, with_setting
from reassemble.files import write_ply
from reassemble.geometry import face_areas, make_transform, random_rotation, sample_surface, transform_points
from reassemble.metrics import ScoringFragment, evaluate

from .conftest import SMALL_COW

# ---- a tiny dataset ------------------------------------------------------------------------


def _tetra(center, size):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) * size + center
    return v, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def _tree(root):
    """Breaking Bad layout (2 and 3 pieces), a break puzzle, and folders that are no set."""
    for k in range(2):
        write_ply(root / "everyday/Vase/v1/fractured_0" / f"piece_{k}.ply", *_tetra([k, 0, 0], 1.0))
    for k in range(3):
        write_ply(root / "everyday/Vase/v1/fractured_1" / f"piece_{k}.ply", *_tetra([k, 0, 0], 1.0))
    write_ply(root / "lonely/one/fractured_0/piece_0.ply", *_tetra([0, 0, 0], 1.0))  # one mesh: no set
    for k in range(2):
        write_ply(root / "_cache" / f"p{k}.ply", *_tetra([k, 0, 0], 1.0))  # skipped
        write_ply(root / "puzzle/fragments" / f"fragment_0{k}.ply", *_tetra([k, 0, 0], 1.0))
    (root / "notes").mkdir()
    (root / "notes/readme.txt").write_text("no meshes here")
    gt = {"format": "reassemble-ground-truth/1", "object": {"bbox_min": [0, 0, 0], "bbox_max": [2, 1, 1]},
          "fragments": {f"fragment_0{k}": {"transform": np.eye(4).tolist(), "file": f"fragments/fragment_0{k}.ply"}
                        for k in range(2)}}
    (root / "puzzle/ground_truth.json").write_text(json.dumps(gt))
    return root


def test_discover_sets(tmp_path):
    sets = discover(_tree(tmp_path))
    assert [(s.id, s.kind, s.pieces, s.category) for s in sets] == [
        ("everyday/Vase/v1/fractured_0", "assembled", 2, "everyday/Vase"),
        ("everyday/Vase/v1/fractured_1", "assembled", 3, "everyday/Vase"),
        ("puzzle", "puzzle", 2, None),
    ]
    assert [s.id for s in select(sets, pieces=(3, 20))] == ["everyday/Vase/v1/fractured_1"]
    sample = select(sets, limit=2, seed=4)
    assert len(sample) == 2 and sample == select(sets, limit=2, seed=4)


# ---- the metrics against the reference code ------------------------------------------------
# A numpy port of the Breaking Bad benchmark's evaluation, multi_part_assembly
# (github.com/Wuziyi616/multi_part_assembly), multi_part_assembly/utils/eval_utils.py at commit
# bad96211b737637dd16c203264a606180d17c75e: calc_part_acc, trans_metrics, rot_metrics;
# utils/rotation.py (882efe5) qeuler(q, 'zyx'); utils/loss.py (dd484b4) shape_cd_loss with
# training=False; the chamfer kernel (utils/chamfer) returns squared distances. Parts are
# re-centred on their points' mean (the dataset's _recenter_pc), translations are those of
# the centres. The reference runs in float32 on a GPU; the port is float64 (same formulas).


def _ref_chamfer(a, b):
    d = ((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)  # brute force, as the CUDA kernel
    return d.min(1), d.min(0)


def _ref_quat(R):
    """Rotation matrix -> unit quaternion (w, x, y, z) (Shepperd's method; qeuler is sign-invariant)."""
    t = np.trace(R)
    if t > 0:
        s = np.sqrt(t + 1.0) * 2
        return np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s])
    i = int(np.argmax(np.diag(R)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k]) * 2
    q = np.empty(4)
    q[0] = (R[k, j] - R[j, k]) / s
    q[1 + i] = 0.25 * s
    q[1 + j] = (R[j, i] + R[i, j]) / s
    q[1 + k] = (R[k, i] + R[i, k]) / s
    return q


def _ref_qeuler_zyx_deg(q):
    q0, q1, q2, q3 = q
    x = np.arctan2(2 * (q0 * q1 + q2 * q3), 1 - 2 * (q1 * q1 + q2 * q2))
    y = np.arcsin(np.clip(2 * (q0 * q2 - q1 * q3), -1, 1))
    z = np.arctan2(2 * (q0 * q3 + q1 * q2), 1 - 2 * (q2 * q2 + q3 * q3))
    return np.array([x, y, z]) * 180.0 / np.pi


def _reference(points, T_pred, T_gt, scale):
    """part_acc, rot RMSE (Euler), trans RMSE, shape chamfer of one shape, as the reference."""
    pcs, t1, t2, r1, r2 = [], [], [], [], []
    for p, Tp, Tg in zip(points, T_pred, T_gt):
        c = p.mean(0)
        pcs.append((p - c) * scale)
        t1.append((Tp[:3, :3] @ c + Tp[:3, 3]) * scale)
        t2.append((Tg[:3, :3] @ c + Tg[:3, 3]) * scale)
        r1.append(Tp[:3, :3])
        r2.append(Tg[:3, :3])
    pts1 = [pc @ R.T + t for pc, R, t in zip(pcs, r1, t1)]  # transform_pc: rotate, then translate
    pts2 = [pc @ R.T + t for pc, R, t in zip(pcs, r2, t2)]
    loss = np.array([sum(d.mean() for d in _ref_chamfer(a, b)) for a, b in zip(pts1, pts2)])
    part_acc = float((loss < 0.01).sum() / len(loss))
    dt = np.array(t1) - np.array(t2)
    trans_rmse = float(np.mean((dt**2).mean(-1) ** 0.5))
    deg1 = np.array([_ref_qeuler_zyx_deg(_ref_quat(R)) for R in r1])
    deg2 = np.array([_ref_qeuler_zyx_deg(_ref_quat(R)) for R in r2])
    diff = np.minimum(np.abs(deg1 - deg2), 360.0 - np.abs(deg1 - deg2))
    rot_rmse = float(np.mean((diff**2).mean(-1) ** 0.5))
    d1, d2 = _ref_chamfer(np.vstack(pts1), np.vstack(pts2))
    n = len(points[0])
    shape_cd = float(np.mean((d1 + d2).reshape(len(points), n).mean(-1)))
    return {"part_acc": part_acc, "rot_rmse_euler_deg": rot_rmse, "trans_rmse": trans_rmse, "shape_cd": shape_cd}


def test_metrics_match_the_reference_code_on_20_predictions():
    rng = np.random.default_rng(22)
    frags = []
    for k in range(4):
        v, f = _tetra(rng.uniform(-1, 1, 3), 0.5 + 0.3 * k)
        T = make_transform(random_rotation(rng), rng.uniform(-2, 2, 3))
        frags.append(ScoringFragment(f"p{k}", transform_points(np.linalg.inv(T), v), f, T))
    allv = np.vstack([transform_points(f.T_world_fragment, f.vertices) for f in frags])
    lo, hi = allv.min(0), allv.max(0)
    scale = 1.0 / (hi - lo).max()
    n = 200
    sample = np.random.default_rng(5)  # the samples evaluate draws with seed 5
    points = [sample_surface(f.vertices, f.faces, n, rng=sample)[0] for f in frags]
    T_gt = np.array([f.T_world_fragment for f in frags])
    largest = int(np.argmax([face_areas(f.vertices, f.faces).sum() for f in frags]))
    checked = 0
    for trial in range(20):
        # small to large errors (some under the 0.01 threshold, some over), rotations near 180 degrees
        size = [0.005, 0.02, 0.1, 0.5, 3.0][trial % 5]
        T_pred = []
        for T in T_gt:
            axis = rng.normal(size=3)
            angle = np.pi - 1e-3 if trial == 19 else size * rng.normal()
            dR = Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix()
            T_pred.append(make_transform(dR @ T[:3, :3], T[:3, 3] + size * rng.normal(size=3)))
        T_pred = np.array(T_pred)
        pred = {f.name: {"transform": T, "placed": True} for f, T in zip(frags, T_pred)}
        ours = evaluate(frags, pred, bbox_min=lo, bbox_max=hi, n_points=n, seed=5)["alignments"]
        anchored = (T_gt[largest] @ np.linalg.inv(T_pred[largest]))[None] @ T_pred
        for mode, T_ref in (("as_given", T_pred), ("anchor_largest", anchored)):
            ref = _reference(points, T_ref, T_gt, scale)
            for key, value in ref.items():
                assert ours[mode]["summary"][key] == pytest.approx(value, abs=1e-6, rel=1e-6), (trial, mode, key)
                checked += 1
    assert checked == 20 * 2 * 4


# ---- the machinery, with stand-in solvers --------------------------------------------------


def identity_solver(meshes, *, config):
    """Every piece left where it is given (wrong, but scored)."""
    return {n: {"transform": np.eye(4), "placed": True} for n in meshes}, {}


def failing_solver(meshes, *, config):
    if len(meshes) == 3:
        raise ValueError("no luck with three pieces")
    if len(meshes) == 4:
        time.sleep(60)
    return identity_solver(meshes, config=config)


def killing_solver(meshes, *, config):
    """Kills its Dask worker the first time it sees 3 pieces (the marker file says it did)."""
    import psutil

    marker = os.environ["REASSEMBLE_TEST_MARKER"]
    if len(meshes) == 3 and not os.path.exists(marker):
        open(marker, "w").close()
        # the solving process <- its fork server <- the worker
        os.kill(psutil.Process(os.getppid()).ppid(), signal.SIGKILL)
        time.sleep(30)
    return identity_solver(meshes, config=config)


def labelling_solver(meshes, *, config):
    """The identity, and the first face of every piece as its fracture."""
    predicted, info = identity_solver(meshes, config=config)
    for name, (_, f) in meshes.items():
        predicted[name]["fracture"] = np.arange(len(f)) == 0
    return predicted, info


def fracture_faces(*, bench_set, meshes, predicted):
    """An extra score: the fracture faces the solver gave, over the set."""
    return {"set": bench_set.id, "fracture_faces": int(sum(p["fracture"].sum() for p in predicted.values())),
            "faces": sum(len(f) for _, f in meshes.values())}


def test_extra_scores_are_computed_in_the_sets_process_and_kept(tmp_path):
    root = _tree(tmp_path / "t")
    sets = discover(root)
    rec = run_set(sets[1], config=Config(), solver=labelling_solver, extra=fracture_faces, isolate=False)
    assert rec["error"] is None and rec["extra"] == {"set": sets[1].id, "fracture_faces": 3, "faces": 12}
    # through bench: in the child process of a Dask worker, into results.jsonl, under its own key
    summary = bench(root, tmp_path / "out", config=Config(), jobs=1, solver=labelling_solver, extra=fracture_faces,
                    only={s.id for s in sets[:2]})
    key = options_key(Config(), n_points=1000, solver=labelling_solver, extra=fracture_faces)
    assert summary["key"] == key and key != options_key(Config(), n_points=1000, solver=labelling_solver)
    records = read_results(tmp_path / "out/results.jsonl", key=key)
    assert {r["extra"]["fracture_faces"] for r in records.values()} == {2, 3}
    assert "extra" not in run_set(sets[1], config=Config(), solver=labelling_solver, isolate=False)


def tqdm_then_sleep(seconds):
    """What a solve does: a progress bar (tqdm's lock is a POSIX semaphore), then work."""
    from tqdm import tqdm

    for _ in tqdm(range(3), disable=True):
        pass
    time.sleep(seconds)
    return {}


def test_the_solving_processes_leak_no_semaphore(tmp_path):
    """A child that answers and one killed at its timeout: no "leaked semaphore" warning from
    multiprocessing's resource tracker when the parent ends."""
    script = ("from reassemble.bench import _in_child, _Stopped\n"
              "from tests.test_bench import tqdm_then_sleep\n"
              "print(_in_child(tqdm_then_sleep, {'seconds': 0}, timeout=None, memory_limit=None))\n"
              "try:\n    _in_child(tqdm_then_sleep, {'seconds': 30}, timeout=1, memory_limit=None)\n"
              "except _Stopped as exc:\n    print(exc)\n")
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120,
                          cwd=os.path.dirname(os.path.dirname(__file__)))
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == ["{}", "timeout (1 s)"]
    assert "leaked" not in done.stderr and "resource_tracker" not in done.stderr, done.stderr


def test_run_set_records_errors_instead_of_raising(tmp_path):
    bad = tmp_path / "bad"
    bad.mkdir()
    for k in range(2):
        (bad / f"piece_{k}.obj").write_text("this is not a mesh\n")
    rec = run_set(BenchSet("bad", str(bad), "assembled", 2, None), config=Config(), isolate=False)
    assert rec["error"] and "metrics" not in rec and rec["time_s"] >= 0
    ok = _tree(tmp_path / "t")
    rec = run_set(discover(ok)[1], config=Config(), solver=failing_solver, isolate=False)
    assert rec["error"].startswith("ValueError: no luck with three pieces (at test_bench.py:")
    rec = run_set(discover(ok)[0], config=Config(), solver=identity_solver, isolate=False)
    assert rec["error"] is None and rec["pieces"] == 2 and 0 <= rec["metrics"]["anchor_largest"]["part_acc"] <= 1


def test_bench_on_two_workers_resumes_and_survives_failures(tmp_path, monkeypatch):
    """2-worker LocalCluster: a set that raises, one over its timeout and one that kills its
    worker on the first try; every set gets its line, and a rerun does no work."""
    root = _tree(tmp_path / "data")
    for k in range(4):
        write_ply(root / "more/x/fractured_0" / f"piece_{k}.ply", *_tetra([k, 0, 0], 1.0))
    out = tmp_path / "out"
    monkeypatch.setenv("REASSEMBLE_TEST_MARKER", str(tmp_path / "killed"))
    summary = bench(root, out, config=Config(), jobs=2, timeout=3, solver=failing_solver)
    lines = [json.loads(x) for x in (out / "results.jsonl").read_text().splitlines()]
    errors = {r["set"]: r["error"] for r in lines}
    assert errors == {"everyday/Vase/v1/fractured_0": None, "puzzle": None,
                      "everyday/Vase/v1/fractured_1": errors["everyday/Vase/v1/fractured_1"],
                      "more/x/fractured_0": "timeout (3 s)"}
    assert errors["everyday/Vase/v1/fractured_1"].startswith("ValueError: no luck")
    assert summary["overall"]["sets"] == 4 and summary["overall"]["failed"] == 2 and summary["ran"] == 4
    for name in ("summary.json", "summary.md", "pa_by_pieces.png", "rotation_errors.png"):
        assert (out / name).stat().st_size > 0
    assert "| 2-5 pieces |" in (out / "summary.md").read_text()
    assert "everyday/Vase" in json.loads((out / "summary.json").read_text())["by_category"]
    # the same options: nothing runs (no cluster is even started)
    again = bench(root, out, config=Config(), jobs=2, timeout=3, solver=failing_solver)
    assert again["ran"] == 0 and again["skipped"] == 4
    assert len((out / "results.jsonl").read_text().splitlines()) == 4


def test_bench_retries_the_set_of_a_killed_worker(tmp_path, monkeypatch):
    """A worker killed mid-run: its set is tried again on a new worker, the others are kept."""
    root = _tree(tmp_path / "data")
    monkeypatch.setenv("REASSEMBLE_TEST_MARKER", str(tmp_path / "killed"))
    out2 = tmp_path / "out2"
    summary = bench(root, out2, config=with_setting(Config(), "seed=1"), jobs=2, timeout=20, solver=killing_solver)
    lines = [json.loads(x) for x in (out2 / "results.jsonl").read_text().splitlines()]
    assert (tmp_path / "killed").exists()
    assert len(lines) == 3 and all(r["error"] is None for r in lines), lines
    assert summary["overall"]["failed"] == 0


def test_a_line_cut_short_by_a_killed_client_is_ignored(tmp_path):
    path = tmp_path / "results.jsonl"
    path.write_text(json.dumps({"key": "k", "set": "a", "error": None}) + "\n"
                    + json.dumps({"key": "other", "set": "b", "error": None}) + "\n" + '{"key": "k", "set": "c", "er')
    assert list(read_results(path, key="k")) == ["a"]


def test_options_key_changes_with_what_changes_results():
    base = options_key(Config(), n_points=1000)
    assert base == options_key(Config(), n_points=1000)
    assert base != options_key(with_setting(Config(), "seed=3"), n_points=1000)
    assert base != options_key(Config(), n_points=500)
    assert base != options_key(Config(), n_points=1000, solver=identity_solver)
    assert base != options_key(Config(), n_points=1000, extra=fracture_faces)


def test_summary_counts_failed_sets_as_wrong():
    ok = {"error": None, "pieces": 2, "time_s": 1.0, "category": None, "rotation_errors_deg": [1.0, 3.0],
          "metrics": {m: {"part_acc": 1.0, "part_acc_strict": 0.5, "solved": False, "rot_rmse_euler_deg": 2.0,
                          "trans_rmse": 0.1, "shape_cd": 0.01, "rot_geodesic_rmse_deg": 3.0}
                      for m in ("as_given", "anchor_largest", "best_anchor")}}
    bad = {"error": "timeout (1 s)", "pieces": 12, "time_s": 1.0, "category": None}
    s = summarize([ok, bad])
    assert s["overall"]["part_acc"] == 0.5 and s["overall"]["rot_rmse_euler_deg"] == 2.0
    assert s["by_pieces_bin"]["11-20"]["part_acc"] == 0.0 and s["errors"] == {"timeout": 1}
    assert s["rotation_histogram"]["counts"][1:3] == [1, 1]


# ---- one real set, end to end, through the command line ------------------------------------


@pytest.mark.slow
def test_bench_command_solves_a_real_set(puzzles, tmp_path, capsys):
    """The smallest smoke-set puzzle (two pieces of the low-resolution cow), in assembled pose
    as Breaking Bad stores it, through `reassemble bench` on one worker (coarser descriptor
    grids than the default: a third of the time, the same result on this set)."""
    from reassemble.puzzle import read_puzzle

    puzzle = read_puzzle(puzzles.puzzle(*SMALL_COW) / "ground_truth.json", with_labels=False)
    for k, (name, m) in enumerate(sorted(puzzle.meshes.items())):
        T = np.array(puzzle.ground_truth["fragments"][name]["transform"])
        write_ply(tmp_path / "data/cow/spot/fractured_0" / f"piece_{k}.ply", transform_points(T, m.vertices), m.faces)
    assert main(["bench", str(tmp_path / "data"), "--out", str(tmp_path / "out"), "--jobs", "1", "--quiet",
                 "--set", "describe.resolution=5"]) == 0
    assert "1 sets (1 run now, 0 from earlier), 0 failed: part accuracy 1.000" in capsys.readouterr().out
    (line,) = (tmp_path / "out/results.jsonl").read_text().splitlines()
    rec = json.loads(line)
    assert rec["error"] is None and rec["metrics"]["anchor_largest"]["part_acc_strict"] == 1.0
    assert rec["timings_s"]["solve"] > 0 and rec["category"] == "cow"
