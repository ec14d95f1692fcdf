"""Each setting declared once (``options.py``): its field's flag, default, reading and checks
all come from the one declaration, for the walkthrough's ``WalkConfig`` and the scene's
``SceneSpec``."""

import argparse
import dataclasses

import pytest

from multigpu.cli import build_parser
from multigpu.config import WalkConfig
from multigpu.core.stereo import UNSHOWN
from multigpu.errors import InputError
from multigpu.flags import spec, walk_config
from multigpu.options import declared, flag_of
from multigpu.scene.models import SceneSpec


def _walk(*flags):
    return walk_config(build_parser().parse_args(["walkthrough", *flags]))


def _actions() -> dict:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return {a.dest: a for a in sub.choices["walkthrough"]._actions}


def test_no_flags_give_the_configurations_defaults():
    assert _walk() == WalkConfig()
    assert spec(build_parser().parse_args(["walkthrough"])) == SceneSpec()


@pytest.mark.parametrize("cls", [WalkConfig, SceneSpec])
def test_every_declared_field_has_its_one_flag(cls):
    actions = _actions()
    for f, opt in declared(cls):
        a = actions[f.name]
        assert a.option_strings == [flag_of(f.name, opt)] and a.help
    undeclared = {f.name for f in dataclasses.fields(cls)} - {f.name for f, _ in declared(cls)}
    assert undeclared == ({"scene", "displays", "positions", "fullscreen", "gpus", "poses", "corners", "right_eye",
                           "mpcdi", "focus", "output_colors", "mpcdi_right"}
                          if cls is WalkConfig
                          else {"ranks", "lods", "step", "live"})


def test_every_choice_and_switch_reaches_its_field():
    """Each value a choice flag takes, and each switch, lands in its field (a flag wired to
    the wrong field, or read wrong, changes another)."""
    base = WalkConfig()
    for f, opt in declared(WalkConfig):
        if opt.choices is not None:
            for value in opt.choices():  # every value stands alone (one that needs another flag fails here)
                if f.name == "stereo" and value in UNSHOWN:  # named, so that its refusal can say why
                    with pytest.raises(InputError, match=f"--stereo {value}: "):
                        _walk(flag_of(f.name, opt), value)
                    continue
                # how stereo eyes are shared (a rank for each eye: a passive wall's)
                with_stereo = ["--stereo", "passive" if value == "own" else "anaglyph"] if f.name == "eyes" else []
                assert getattr(_walk(flag_of(f.name, opt), value, *with_stereo), f.name) == value
        elif opt.switch or opt.negate:
            cfg = _walk(flag_of(f.name, opt))
            assert getattr(cfg, f.name) is (not getattr(base, f.name))
            assert {g.name for g in dataclasses.fields(cfg) if getattr(cfg, g.name) != getattr(base, g.name)} == {
                f.name}


@pytest.mark.parametrize("flags,field,value", [
    (["--grid", "1x3"], "grid", (1, 3)), (["--tile", "64x48"], "tile", (64, 48)),
    (["--mullion", "4x2"], "mullion", (4, 2)), (["--offset", "1,2,3"], "offset", (1.0, 2.0, 3.0)),
    (["--dark-tiles", "3,1"], "dark", (1, 3)), (["--frames", "7"], "frames", 7),
    (["--render-scale", "0.5"], "render_scale", 0.5), (["--resume-at", "9"], "resume_at", 9),
    (["--present", "window", "--monitor"], "monitor", (-1, -1)),
    (["--present", "window", "--monitor", "10,20"], "monitor", (10, 20)),
])
def test_read_flags_reach_their_fields(flags, field, value):
    assert getattr(_walk(*flags), field) == value


@pytest.mark.parametrize("flags,needle", [
    (["--dark-tiles", "a"], "--dark-tiles must be tile numbers separated by commas, got 'a'"),
    (["--dark-tiles", "9"], "--dark-tiles must name some of the tiles 0..3, got [9]"),
    (["--no-overlay", "--mosaic-every", "-2"], "--mosaic-every must be >= 0 (0 = never), got -2"),
    (["--tile", "20000x8"], "--tile must be at most 16384 pixels per side, got 20000x8"),
    (["--cluster", "x"], "--cluster must be 'auto' or a number of triangles (0: never), got 'x'"),
    (["--triangles", "10"], "--triangles must be >= 1000, got 10"),
])
def test_bad_values_name_their_flag(flags, needle):
    with pytest.raises(InputError) as e:
        _walk(*flags)
    assert str(e.value) == needle


def test_the_entry_point_declares_flags_as_data():
    """cli.py, tools.py and commands.py make at most 10 ``add_argument`` calls (the subcommands'
    arguments are ``commands.COMMANDS``, added in one loop; the walkthrough's come from the
    declared options), and each shared flag has one helper."""
    import ast
    from pathlib import Path

    pkg = Path(__file__).resolve().parents[1] / "multigpu"
    calls = 0
    for name in ("cli.py", "tools.py", "commands.py"):
        for node in ast.walk(ast.parse((pkg / name).read_text())):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "add_argument":
                calls += 1
    assert calls <= 10, calls
    from multigpu.commands import COMMANDS

    outs = [a for c in COMMANDS for a in c.args if a.names == ("--out",)]
    assert outs and all(("default" in a.kw) != a.kw.get("required", False) for a in outs)
    kinds = [a for c in COMMANDS for a in c.args if a.names == ("--path-kind",)]
    assert kinds and all(a.kw["choices"] == ("walkthrough", "orbit", "still") for a in kinds)
