"""The dataclass -> flags helper: help text from field docstrings, enum and
Literal choices, switches, required flags, parsers, defaults equal to the
dataclass's, and bad values ending in one line with exit status 2."""
from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass, field
from typing import Literal

import pytest

from nbrdf.cli.config import Parser, add_arguments, build, field_docs, flag_name
from nbrdf.cli.main import build_parser, nbrdf_main, run_guarded
from nbrdf.imaging.tonemap import ToneMap
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.methods import Method


def _pair(text: str) -> tuple[int, int]:
    try:
        a, b = (int(x) for x in text.split(":"))
    except ValueError:
        raise NbrdfError(f"--pair: expected A:B, got {text!r}") from None
    return a, b


@dataclass
class Demo:
    """A config used only by these tests."""

    out: str
    """where the result goes"""
    theta_i: float = 30.0
    """incidence angle,
    degrees"""
    count: int | None = None
    """how many (default: all)"""
    method: Method = Method.NEURAL
    """evaluation method"""
    kind: Literal["a", "b"] = "b"
    """which kind"""
    verbose: bool = False
    """say more"""
    colour: bool = True
    """draw in colour"""
    pair: tuple[int, int] = field(default=(1, 2), metadata={"parse": _pair, "shown": "1:2"})
    """two numbers A:B"""
    undocumented: str = "x"


def parser() -> Parser:
    p = Parser(prog="demo")
    add_arguments(p, Demo)
    return p


def test_field_docs_are_the_string_literals_under_the_fields():
    docs = field_docs(Demo)
    assert docs["out"] == "where the result goes"
    assert docs["theta_i"] == "incidence angle, degrees"  # whitespace of a multi-line docstring folded
    assert "undocumented" not in docs


def test_help_text_defaults_and_choices_come_from_the_dataclass():
    text = " ".join(parser().format_help().split())
    assert "--theta-i THETA_I incidence angle, degrees (default: 30.0)" in text
    assert "--method {reference,neural,projected,refined,calibrated,analytic,belcour} evaluation method (default: neural)" in text
    assert "--kind {a,b} which kind (default: b)" in text
    assert "--no-colour draw in colour" in text and "--verbose say more" in text
    assert "two numbers A:B (default: 1:2)" in text
    assert "--out OUT where the result goes" in text and "(default: None)" not in text


def test_no_flags_give_the_dataclass_defaults():
    got = build(Demo, parser().parse_args(["--out", "o"]))
    assert got == Demo(out="o")
    assert isinstance(got.method, Method) and got.method is Method.NEURAL


def test_every_flag_converts_to_the_field_type():
    got = build(Demo, parser().parse_args(
        ["--out", "o", "--theta-i", "-12.5", "--count", "3", "--method", "reference", "--kind", "a", "--verbose",
         "--no-colour", "--pair", "7:9", "--undocumented", "y"]))
    assert got == Demo(out="o", theta_i=-12.5, count=3, method=Method.REFERENCE, kind="a", verbose=True,
                       colour=False, pair=(7, 9), undocumented="y")


@pytest.mark.parametrize("argv,needle", [
    ([], "--out"),                                              # a required flag missing
    (["--out", "o", "--method", "fast"], "invalid choice: 'fast'"),
    (["--out", "o", "--count", "many"], "invalid int value: 'many'"),
    (["--out", "o", "--theta-i", "nan?"], "invalid float value"),
    (["--out", "o", "--bogus"], "unrecognized arguments: --bogus"),
])
def test_bad_values_are_one_nbrdf_error(argv, needle):
    with pytest.raises(NbrdfError, match="demo: .*" + needle.replace("?", r"\?")) as e:
        build(Demo, parser().parse_args(argv))
    assert "\n" not in str(e.value)


def test_a_field_parser_error_is_the_fields_own_line():
    with pytest.raises(NbrdfError, match=r"^--pair: expected A:B, got '7'$"):
        build(Demo, parser().parse_args(["--out", "o", "--pair", "7"]))


def test_run_guarded_prints_one_line_and_exits_2(capsys):
    def bad() -> int:
        build(Demo, parser().parse_args(["--out", "o", "--method", "fast"]))
        return 0

    assert run_guarded("demo", bad) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("demo: argument --method: invalid choice"), err  # named once


def test_only_exclude_and_overrides():
    p = Parser(prog="demo")
    names = add_arguments(p, Demo, only=("out", "kind", "count"), exclude=("count",), required=("kind",),
                          help={"out": "elsewhere"}, choices={"kind": ("b",)}, defaults={"out": "d"})
    assert names == ["out", "kind"]
    text = " ".join(p.format_help().split())
    assert "--out OUT elsewhere (default: d)" in text and "--kind {b}" in text and "--count" not in text
    with pytest.raises(NbrdfError, match="required: --kind"):
        p.parse_args([])


def test_flag_names():
    assert flag_name("theta_i") == "--theta-i" and flag_name("spp") == "--spp"


def test_enum_words_are_the_mode_enum_values():
    p = Parser(prog="t")

    @dataclass
    class T:
        tonemap: ToneMap = ToneMap.ACES

    add_arguments(p, T)
    assert "--tonemap {" + ",".join(ToneMap.words()) + "}" in p.format_help()
    assert build(T, p.parse_args(["--tonemap", "linear"])).tonemap is ToneMap.LINEAR


def _walk(p, path=()):
    p.format_help()  # adds deferred flags
    subs = [a for a in p._actions if a.__class__.__name__ == "_SubParsersAction"]
    if not subs:
        yield path, p
        return
    for name, sp in subs[0].choices.items():
        yield from _walk(sp, path + (name,))


def test_every_nbrdf_command_has_help_for_every_flag():
    """Each flag of each command says what it is (a docstring reached --help)."""
    seen = 0
    for path, p in _walk(build_parser()):
        for action in p._actions:
            if action.option_strings and action.dest != "help":
                assert action.help and action.help.strip(), (path, action.dest)
                seen += 1
    assert seen > 50


def test_training_flags_default_to_the_training_configs():
    """`nbrdf train ...` with no optional flags builds exactly the training code's configs."""
    from nbrdf.neural.decoder import DEFAULT_WEIGHTS, DecoderSpec
    from nbrdf.training import train_operations as to
    from nbrdf.training import train_sampler as ts
    from nbrdf.training.train_representation import TrainConfig

    p = build_parser()
    a = p.parse_args(["train", "representation", "--data", "d", "--out", "o"])
    assert build(TrainConfig, a, spec=build(DecoderSpec, a, ("width", "depth", "activation", "loss_scale"))) \
        == TrainConfig(data="d", out="o")
    for what, cls in (("leaf", to.LeafConfig), ("layering", to.LayeringConfig), ("sampler", ts.SamplerConfig)):
        argv = ["train", what, "--out", "o"] + (["--data", "d"] if what == "layering" else [])
        a = p.parse_args(argv)
        want = cls(out="o", data="d") if what == "layering" else cls(out="o")
        for f in dataclasses.fields(cls):
            if hasattr(a, f.name) and f.name != "decoder":
                assert getattr(a, f.name) == getattr(want, f.name), (what, f.name)
        assert want.decoder == str(DEFAULT_WEIGHTS)


def test_operation_defaults_are_the_documented_ones():
    """The per-operation defaults the command line has always had (SPEC section 8)."""
    from nbrdf.training import train_operations as to
    from nbrdf.training import train_sampler as ts

    got = {c.__name__: (c.steps, c.batch, c.pairs, c.lr) for c in (to.LeafConfig, to.LayeringConfig, ts.SamplerConfig)}
    assert got == {"LeafConfig": (6000, 32, 128, 2e-3), "LayeringConfig": (5000, 48, 192, 1e-3),
                   "SamplerConfig": (3000, 64, 256, 3e-3)}
    assert (to.LayeringConfig.recursion_steps, to.LayeringConfig.width) == (2000, 256)


@pytest.mark.parametrize("argv,needle", [
    (["train", "leaf", "--out", "o", "--data", "d"], "unrecognized arguments: --data"),
    (["train", "layering", "--out", "o"], "the following arguments are required: --data"),
    (["train", "representation", "--data", "d", "--out", "o", "--device", "tpu"], "invalid choice: 'tpu'"),
    (["train", "representation", "--data", "d", "--out", "o", "--epochs", "0"], "--epochs: 0 must be at least 1"),
    (["train", "sampler", "--out", "o", "--pairs", "0"], "--pairs: 0 must be at least 1"),
    (["bench", "render", "--size", "0x4"], "--size: 0x4 is outside"),
])
def test_training_and_bench_bad_flags_are_one_line(capsys, argv, needle):
    assert nbrdf_main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err


def _float_flags():
    """(command, flag, field type) for every float-typed field of every command's
    config dataclass, from the field types that ``add_arguments`` records on
    each flag (``nbrdf`` subcommands and ``nbrdf-view``)."""
    from nbrdf.cli.view import build_parser as view_parser

    out = []
    for prog, (path, p) in [("nbrdf", w) for w in _walk(build_parser())] + [("nbrdf-view", ((), view_parser()))]:
        for action in p._actions:
            if not action.option_strings or action.dest == "help":
                continue
            tp = getattr(action, "field_type", None)
            assert tp is not None, f"{prog} {' '.join(path)} {action.option_strings[0]}: not a dataclass field"
            if tp is float or (typing.get_origin(tp) is tuple and float in typing.get_args(tp)):
                out.append(((prog, *path), action.option_strings[0], tp))
    return out


FLOAT_FLAGS = _float_flags()


def test_the_float_flags_found_are_all_of_them():
    """The walk reaches every command's float flags (a walk that found none
    would make the test below pass vacuously)."""
    got = {(" ".join(c), f) for c, f, _ in FLOAT_FLAGS}
    for want in [("nbrdf-view", "--exposure"), ("nbrdf-view", "--env-intensity"), ("nbrdf-view", "--point-light"),
                 ("nbrdf train representation", "--lr"), ("nbrdf train representation", "--loss-scale"),
                 ("nbrdf train layering", "--ema"), ("nbrdf lobe", "--theta-i"), ("nbrdf report render", "--noise-target")]:
        assert want in got, want
    assert len(got) >= 20


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "NaN", "1e400"])
@pytest.mark.parametrize("command,flag,tp", FLOAT_FLAGS, ids=[" ".join(c) + " " + f for c, f, _ in FLOAT_FLAGS])
def test_every_float_flag_rejects_non_finite_values(capsys, tmp_path, monkeypatch, command, flag, tp, value):
    """nan, inf and a number that overflows to inf end in one line naming the
    flag and its value, and exit status 2, before any work is done."""
    from nbrdf.cli.view import main as view_main

    monkeypatch.chdir(tmp_path)  # a command that wrongly ran would write here
    text = value if tp is float else ",".join([value, "0", "0"])
    argv = [*command[1:], f"{flag}={text}"]
    rc = view_main(argv) if command[0] == "nbrdf-view" else nbrdf_main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and flag in err[0] and repr(text) in err[0], (rc, err)
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("argv,needle", [
    (["train", "representation", "--data", "d", "--out", "o", "--lr", "0"], "--lr: 0.0 is outside (0, inf)"),
    (["train", "representation", "--data", "d", "--out", "o", "--latent-lr", "-1"], "--latent-lr: -1.0 is outside"),
    (["train", "representation", "--data", "d", "--out", "o", "--latent-reg", "-0.001"], "--latent-reg: -0.001"),
    (["train", "representation", "--data", "d", "--out", "o", "--loss-scale", "0"], "--loss-scale: 0.0 is outside"),
    (["train", "leaf", "--out", "o", "--lr", "-0.1"], "--lr: -0.1 is outside (0, inf)"),
    (["train", "sampler", "--out", "o", "--ema", "1"], "--ema: 1.0 is outside [0, 1)"),
    (["train", "layering", "--out", "o", "--data", "d", "--loss-scale", "-1"], "--loss-scale: -1.0 is outside [0, inf)"),
    (["train", "layering", "--out", "o", "--data", "d", "--relative-scale", "-1"], "--relative-scale: -1.0"),
])
def test_training_rates_and_scales_are_range_checked(capsys, tmp_path, monkeypatch, argv, needle):
    """Learning rates and loss scales out of range end in one line before any data is read."""
    monkeypatch.chdir(tmp_path)
    assert nbrdf_main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err
    assert not (tmp_path / "o").exists()
