"""FE validation (engine/validation): small versions of both cases against their published solutions, the
CLI's table and its one-line refusal without the 'fe' extra, the convergence study's bookkeeping."""

import json
import sys

import numpy as np
import pytest

from engine.cli import main

SPHERE_H10 = 2.8  # sphere scale giving h = 10 (wall thickness 50 / 14 x 2.8)


def fe():
    pytest.importorskip("skfem")
    pytest.importorskip("pyamg")


def test_plate_hole_coarse_recipe_mesh_within_3_percent_of_peterson():
    """The static-stress recipe with every size x 3 (about 420 nodes): the through-thickness mean Kt at the hole
    root within 3 % of Peterson's; in 3-D the root stress is highest at the mid-plane, lowest at the faces."""
    fe()
    from engine.validation import run_case

    case = run_case("plate-hole", scale=3.0)
    kt = case.row("Kt net, through-thickness mean")
    assert kt.reference == pytest.approx(2.508, abs=1e-3)  # Peterson at d/W = 0.2
    assert abs(kt.error) < 0.03, case.table()
    assert case.row("Kt net, faces").computed < kt.computed < case.row("Kt net, mid-plane").computed
    assert case.facts["max reaction / load"] < 1e-6, "the 3-2-1 supports carry no load: the load is balanced"
    assert case.facts["nodes"] < 1000


def test_sphere_coarse_mesh_hoop_stress_and_displacement_against_lame():
    """h = 10 (5 elements through the wall): the inner hoop stress within 2 % on average over the inner
    surface's nodes, the radial displacement within 1 % at every inner and outer node."""
    fe()
    from engine.validation import run_case

    case = run_case("sphere", scale=SPHERE_H10)
    assert case.row("hoop stress at r = a, mean of the nodes").reference == pytest.approx(100 * (1 + 8 / 2) / 7)
    assert abs(case.row("hoop stress at r = a, mean of the nodes").error) < 0.02, case.table()
    for radius in "ab":
        assert abs(case.row(f"u_r at r = {radius}, worst node").error) < 0.01, case.table()
    assert abs(case.row("hoop stress at r = a, worst node").error) < 0.15, case.table()


def test_lame_and_peterson_references():
    from engine.validation.plate_hole import peterson_kt
    from engine.validation.sphere import INNER, MATERIAL, OUTER, PRESSURE, lame

    assert [round(peterson_kt(r), 3) for r in (0.1, 0.2, 0.3, 0.4, 0.5)] == [2.722, 2.508, 2.349, 2.236, 2.159]
    u, radial, hoop = lame(np.array([INNER, OUTER]))
    assert radial == pytest.approx([-PRESSURE, 0.0], abs=1e-12)  # the surface tractions
    a3, b3 = INNER**3, OUTER**3
    assert hoop[0] == pytest.approx(PRESSURE * a3 * (1 + b3 / (2 * a3)) / (b3 - a3))
    strain = (hoop - MATERIAL.nu * (radial + hoop)) / MATERIAL.E  # hoop strain = u / r
    assert u == pytest.approx(strain * np.array([INNER, OUTER]))


def test_cli_prints_the_table_and_exits_0(capsys):
    fe()
    assert main(["validate", "sphere", "--scale", "4"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("sphere: thick hollow sphere")
    assert "hoop stress at r = a, mean of the nodes" in out and "Lamé" in out and "%" in out


def test_cli_without_the_fe_extra_says_what_to_install(capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "skfem", None)  # import skfem now raises ImportError
    assert main(["validate", "plate-hole"]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in captured.err
    assert "scikit-fem" in lines[0] and "pip install 'fuzzymesh[fe]'" in lines[0]


def test_unknown_case_is_one_line(capsys):
    with pytest.raises(SystemExit) as exit:
        main(["validate", "beam"])
    assert exit.value.code == 2
    assert "invalid choice" in capsys.readouterr().err


def test_graded_series_at_scale_1_is_the_recipe():
    """The study's graded meshes scale the placements of static-stress; at scale 1 they size like the recipe."""
    from engine.job import job_from_dict
    from engine.knowledge import load_knowledge
    from engine.pipeline import build_geometry, build_sizing
    from engine.validation.plate_hole import default_size, graded_placements, job

    recipe = job_from_dict(job(1.0))
    assert recipe.recipe == "static-stress"
    geometry_and_seed = {k: v for k, v in job(1.0).items() if k != "recipe"}
    scaled = job_from_dict({**geometry_and_seed, "size": default_size(), "place": graded_placements(1.0)})
    kb = load_knowledge([])
    geometry, features = build_geometry(recipe)
    points = np.random.default_rng(0).uniform(geometry.bounds[0], geometry.bounds[1], (2000, 3))
    assert np.allclose(
        build_sizing(recipe, geometry, features, kb)(points), build_sizing(scaled, geometry, features, kb)(points)
    )
    assert job(2.0)["size"] == pytest.approx(2 * default_size())
    # the study itself reads the sizing defaults without the always-placed thin-wall rule
    bare = job_from_dict(job(1.0, rules=False))
    bare_scaled = job_from_dict(
        {
            **geometry_and_seed,
            "knowledge": [str(k) for k in bare.knowledge],
            "size": default_size(),
            "place": graded_placements(1.0, rules=False),
        }
    )
    study_kb = load_knowledge(bare.knowledge)
    study_sizing = build_sizing(bare, geometry, features, study_kb)
    assert [p.pattern for p in study_sizing.placed] == ["uniform-domain", "hole"]
    assert np.allclose(study_sizing(points), build_sizing(bare_scaled, geometry, features, study_kb)(points))


def test_nodes_at_target_interpolates_where_the_series_stays_within():
    from engine.validation.study import nodes_at

    rows = [{"nodes": n, "error": e} for n, e in ((100, -0.10), (200, -0.04), (400, 0.02), (800, -0.035), (1600, 0.01))]
    # the last mesh above 3 % is the one with 800 nodes; log-log between (800, 3.5 %) and (1600, 1 %)
    expected = np.exp(np.log(800) + (np.log(0.03) - np.log(0.035)) / (np.log(0.01) - np.log(0.035)) * np.log(2))
    assert nodes_at(rows) == pytest.approx(expected)
    assert nodes_at(rows[:2]) is None  # never within 3 %
    assert nodes_at(rows[2:3] + rows[4:]) is None  # within 3 % from its coarsest mesh: not bracketed


def test_study_averages_the_seeds_and_writes_table_json_and_a_small_plot(tmp_path):
    from engine.validation.study import means, nodes_at, write_study

    rows = [
        {
            "series": s,
            "scale": k,
            "size": 5.6 * k,
            "nodes": n,
            "Kt": 2.5,
            "error": e,
            "seconds": {"mesh": 1.0},
            "seed": seed,
        }
        for s, k, n, e, seed in (
            ("graded", 4, 250, -0.05, 0),
            ("graded", 4, 260, -0.03, 1),
            ("graded", 3, 400, -0.01, 0),
            ("graded", 3, 420, -0.02, 1),
            ("uniform", 1.5, 600, -0.06, 0),
            ("uniform", 1.5, 640, -0.04, 1),
            ("uniform", 1, 1700, -0.02, 0),
            ("uniform", 1, 1720, 0.0, 1),
        )
    ]
    series = {name: means([r for r in rows if r["series"] == name]) for name in ("graded", "uniform")}
    assert [(p["scale"], p["nodes"], p["error"], p["error_min"]) for p in series["graded"]] == [
        (4, 255, pytest.approx(-0.04), -0.05),
        (3, 410, pytest.approx(-0.015), -0.02),
    ]
    at = {name: nodes_at(points) for name, points in series.items()}
    study = {
        "case": "plate-hole",
        "target": 0.03,
        "Kt_peterson": 2.508,
        "seeds": [0, 1],
        "rows": rows,
        "series": series,
        "nodes_at_target": at,
        "ratio": at["uniform"] / at["graded"],
    }
    paths = write_study(study, tmp_path)
    assert json.loads(paths[0].read_text())["series"]["uniform"][1]["nodes"] == 1710
    table = paths[1].read_text()
    assert "| graded | 4 | 22.4 | 255 |" in table and f"{study['ratio']:.1f} times as many nodes" in table
    assert paths[2].read_bytes()[:4] == b"\x89PNG" and paths[2].stat().st_size < 200_000


def test_hollow_sphere_octant_is_named_for_its_boundary_conditions(built):
    shape, features = built("hollow_sphere_octant")
    names = sorted(n for p in features.patches for n in p.names)
    assert names == ["inner", "outer", "symmetry-x", "symmetry-y", "symmetry-z"]
    exact = np.pi / 6 * (100.0**3 - 50.0**3)
    assert shape.geometry.volume == pytest.approx(exact, rel=2e-3)  # faceted within 0.1 % of the radii
    centres = shape.geometry.mesh.triangles_center
    for name, radius in (("inner", 50.0), ("outer", 100.0)):
        (patch,) = [p for p in features.patches if name in p.names]
        assert (np.linalg.norm(centres[patch.faces], axis=1) > radius * (1 - 1e-3)).all()


def test_the_solve_does_not_depend_on_numpy_s_global_random_state():
    """pyamg's default prolongation smoother estimates a spectral radius from numpy's global generator: two solves
    of one mesh differed (and one diverged); the validation's solver gives the same numbers whatever that state."""
    fe()
    from engine.validation import run_case

    tables = []
    for state in (1, 2):
        np.random.seed(state)
        case = run_case("sphere", scale=SPHERE_H10)
        tables.append([(row.quantity, row.computed) for row in case.rows])
    assert tables[0] == tables[1]


def test_a_solve_cg_does_not_finish_is_done_directly(monkeypatch):
    """Where CG + AMG stops short (here: one step allowed), a sparse LU solve gives the same answers."""
    fe()
    from engine.validation import elasticity, run_case

    iterative = run_case("sphere", scale=SPHERE_H10)
    monkeypatch.setattr(elasticity, "CG_STEPS", 1)
    direct = run_case("sphere", scale=SPHERE_H10)
    for a, b in zip(iterative.rows, direct.rows):
        assert b.computed == pytest.approx(a.computed, rel=1e-7), a.quantity
