"""Testing an effect of one's own against a finished close-loop (pyomo_heli.workflows.check_effect, the
``check-effect`` command), on the small drag-rise instance of tests/test_discovery.py."""
import dataclasses
import json

import pytest
from test_discovery import _loop

from pyomo_heli.cli import main
from pyomo_heli.flighttest.held_out_effects import DragRise
from pyomo_heli.workflows.check_effect import check_effect


class BoundedDragRise(DragRise):
    """The held-out drag rise as an engineer's hypothesis: its strength free within bounds."""

    def parameters(self):
        return [dataclasses.replace(s, bounds=(-1.5, 1.5), scale=0.15) if s.name == "k_dr" else s
                for s in super().parameters()]


@pytest.fixture(scope="module")
def drag_loop(tmp_path_factory):
    """A finished loop (iteration 0 only) on a small flight test with the drag rise (k_dr = 0.15) held out."""
    root = tmp_path_factory.mktemp("drag")
    cfg, doc = _loop(root, "[truth.effects.drag_rise]\nk_dr = 0.15\n", seed=31)
    return cfg, doc, root / "loop"


@pytest.fixture(scope="module")
def drag_check(drag_loop):
    """check_effect of the bounded drag rise on that loop (the function's own result)."""
    return check_effect(drag_loop[2], BoundedDragRise(), progress=lambda s: None)


def test_the_true_effect_is_estimated_and_explains_what_the_generic_term_does(drag_loop, drag_check):
    """The drag rise's own form at the kept model: its strength within 3 standard errors of the truth's 0.15, a
    larger LR than the generic term the step described, and that term adds nothing significant once it is in
    (p >= 0.01); tested at the level the step used."""
    cfg, doc, loop = drag_loop
    step = doc["iterations"][0]["discovery"]
    r = drag_check
    t, e = r["term"], r["encompassing"]
    assert r["iteration"] == 0 and r["level"] == step["level"]
    assert r["against"]["name"] == (step.get("discovered") or step["best_generic"])["name"]
    assert abs(t["estimate"] - 0.15) < 3 * t["se"], t
    assert t["LR"] > r["against"]["LR"], (t["LR"], r["against"]["LR"])
    assert e["p_G_given_P"] >= 0.01 and e["p_P_given_G"] < 0.01, e


def test_a_wrong_hypothesis_is_not_significant(drag_loop):
    """The nose-up moment bump at hover (a library term, by name) holds none of the drag rise: not significant, and
    it does not explain what the step's generic term explains."""
    _, _, loop = drag_loop
    r = check_effect(loop, "dM_bump00", progress=lambda s: None)
    assert not r["significant"] and r["term"]["p"] > 0.01
    # the corrected LR decides, so the size from which a bump of this shape would be significant is given: above
    # the estimate, as the term is not
    assert r["criterion"] == "likelihood ratio" and r["term"]["detectable"] > abs(r["term"]["estimate"])
    assert not r["encompassing"]["encompasses"]


def test_the_command_prints_the_tests_and_writes_json(drag_loop, drag_check, tmp_path, capsys):
    """``pyomo-heli check-effect`` with FILE.py:CLASS: the same numbers as the function, printed and in --json."""
    _, _, loop = drag_loop
    f = tmp_path / "my_effects.py"
    f.write_text("import dataclasses\nfrom pyomo_heli.flighttest.held_out_effects import DragRise\n\n"
                 "class Mine(DragRise):\n    def parameters(self):\n"
                 "        return [dataclasses.replace(s, bounds=(-1.5, 1.5), scale=0.15) if s.name == 'k_dr' else s\n"
                 "                for s in super().parameters()]\n")
    assert main(["check-effect", str(loop), "--effect", f"{f}:Mine", "--json", str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    r = json.loads((tmp_path / "r.json").read_text())
    ref = drag_check
    assert r["term"]["estimate"] == pytest.approx(ref["term"]["estimate"], rel=1e-6)
    assert f"k_dr = {r['term']['estimate']:.4g}" in out and ("not significant" in out) != r["significant"]
    assert f"against {ref['against']['name']}:" in out
    assert f"significant from |k_dr| >= {r['term']['detectable']:.2g}" in out


@pytest.mark.parametrize("effect, message", [
    ("no_such_term", "option --effect: unknown candidate extension 'no_such_term'"),
    ("missing.py:X", "option --effect: file missing.py not found"),
    ("json:Nothing", "option --effect: json has no extension class 'Nothing'"),
    ("{tmp}/nobounds.py:NoBounds", "option --effect: NoBounds's strength 'k' has no bounds"),
])
def test_bad_effects_are_one_line_exit_2(tmp_path, capsys, effect, message):
    (tmp_path / "nobounds.py").write_text(
        "from pyomo_heli.physics.extensions import Extension\nfrom pyomo_heli.physics.parameters import ParameterSpec\n"
        "class NoBounds(Extension):\n    name = 'nb'\n    strength = 'k'\n"
        "    def parameters(self):\n        return [ParameterSpec('k', 0.0, '-', 'x', 'y')]\n")
    assert main(["check-effect", str(tmp_path), "--effect", effect.format(tmp=tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


def test_an_iteration_the_loop_did_not_run_is_named(drag_loop, capsys):
    _, _, loop = drag_loop
    assert main(["check-effect", str(loop), "--effect", "dM_one", "--iteration", "3"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no iteration 3 (the loop ran iterations 0)" in err[0], err
