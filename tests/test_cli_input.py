"""Bad command lines: every user error ends with exit code 2 and one line on stderr
(``igraph-fight: error: ...``), never a traceback; numeric options are range-checked when parsed."""
from __future__ import annotations

import pytest

from igraph_fight.cli import build_parser, main


def _one_line_error(argv: list[str], capsys) -> str:
    """Run ``igraph-fight argv`` in-process; assert exit code 2 and one error line; return it."""
    rc = main([str(a) for a in argv])
    cap = capsys.readouterr()
    lines = [x for x in cap.err.splitlines() if x.strip()]
    assert rc == 2, (argv, rc, cap.err[-2000:])
    assert len(lines) == 1 and lines[0].startswith("igraph-fight: error: "), (argv, cap.err[-2000:])
    assert "Traceback" not in cap.err
    return lines[0]


#: (command line, text the error line must hold): refused while parsing, no file read
PARSE_ERRORS = [
    (["fight", "--graph", "g.igz", "--depth-a", "-2"], "--depth-a: must be an integer in 1..12"),
    (["fight", "--graph", "g.igz", "--depth-b", "13"], "--depth-b: must be an integer in 1..12"),
    (["fight", "--graph", "g.igz", "--depth-a", "two"], "not an integer: 'two'"),
    (["fight", "--graph", "g.igz", "--seconds", "-5"], "--seconds: must be > 0"),
    (["fight", "--graph", "g.igz", "--seconds", "0"], "--seconds: must be > 0"),
    (["fight", "--graph", "g.igz", "--seconds", "nan"], "--seconds: must be finite"),
    (["fight", "--graph", "g.igz", "--seed", "-1"], "--seed: must be an integer >= 0"),
    (["fight", "--graph", "g.igz", "--swap-a", "2"], "--swap-a: expected T:STYLE"),
    (["fight", "--graph", "g.igz", "--swap-a=-3:outboxer"], "swap time must be a finite number of seconds >= 0"),
    (["policy", "--graph", "g.igz", "--gamma", "nan"], "--gamma: must be finite"),
    (["policy", "--graph", "g.igz", "--gamma", "5"], "--gamma: must lie in (0, 1]"),
    (["policy", "--graph", "g.igz", "--gamma", "-1"], "--gamma: must lie in (0, 1]"),
    (["policy", "--graph", "g.igz", "--depth", "1000000"], "--depth: must be an integer in 1..12"),
    (["policy", "--graph", "g.igz", "--repeat", "0"], "--repeat: must be an integer >= 1"),
    (["evaluate", "--graph", "g.igz", "--workers", "0"], "--workers: must be an integer >= 1"),
    (["evaluate", "--graph", "g.igz", "--bouts", "-1"], "--bouts: must be an integer >= 1"),
    (["evaluate", "--graph", "g.igz", "--depths", "1,0"], "--depths: must be an integer in 1..12"),
    (["evaluate", "--graph", "g.igz", "--seconds", "inf"], "--seconds: must be finite"),
    (["train-rl", "--graph", "g.igz", "--out", "x.pt", "--minutes", "-1"], "--minutes: must be > 0"),
    (["train-rl", "--graph", "g.igz", "--out", "x.pt", "--seed", "-3"], "--seed: must be an integer >= 0"),
    (["mocap", "inspect", "x.bvh", "--fps", "0"], "--fps: must be > 0"),
    (["mocap", "segment", "--library-fps", "-30"], "--library-fps: must be > 0"),
    (["demo", "--seed", "-1"], "--seed: must be an integer >= 0"),
    (["tracker", "eval", "--walks", "0"], "--walks: must be an integer >= 1"),
    (["tracker", "eval", "--workers", "0"], "--workers: must be an integer >= 1"),
    (["tracker", "eval", "--actions", "-4"], "--actions: must be an integer >= 1"),
    (["tracker", "eval", "--physics-hz", "0"], "--physics-hz: must be > 0"),
    (["tracker", "render", "--out", "x.png", "--seconds", "-1"], "--seconds: must be > 0"),
    (["tracker", "train", "--minutes", "0", "--out", "x.pt"], "--minutes: must be > 0"),
    (["tracker", "train", "--minutes", "1", "--out", "x.pt", "--push-prob", "2"], "--push-prob: must lie in [0, 1]"),
    (["tracker", "bouts", "fight", "--graph", "g.igz", "--depth-a", "0"], "--depth-a: must be an integer in 1..12"),
    (["tracker", "bouts", "series", "--graph", "g.igz", "--bouts", "0"], "--bouts: must be an integer >= 1"),
    (["tracker", "rl", "eval", "--graph", "g.igz", "--depth", "99"], "--depth: must be an integer in 1..12"),
    (["tracker", "rl", "train", "--tracker", "pd", "--out", "x.pt", "--minutes", "-2"], "--minutes: must be > 0"),
    (["tracker", "hit-model", "collect", "--graph", "g.igz", "--out", "x.npz", "--explore", "2"],
     "--explore: must lie in [0, 1]"),
    (["fight", "--graph", "g.igz", "--bogus"], "unrecognized arguments: --bogus"),
    (["nosuch"], "invalid choice: 'nosuch'"),
    ([], "the following arguments are required: COMMAND"),
]


@pytest.mark.parametrize("argv,text", PARSE_ERRORS, ids=[" ".join(a[:3]) + " " + a[-1] if a else "none"
                                                         for a, _ in PARSE_ERRORS])
def test_out_of_range_options_are_refused_in_one_line(argv, text, capsys):
    line = _one_line_error(argv, capsys)
    assert text in line, line


def test_swap_beyond_the_bout_and_missing_inputs_are_refused(tmp_path, capsys):
    """No graph is read: the swap time, the swap's style and missing files are checked first."""
    line = _one_line_error(["fight", "--graph", tmp_path / "g.igz", "--seconds", "5", "--swap-a", "30:outboxer"], capsys)
    assert "--swap-a 30:outboxer" in line and "beyond the bout's end (5 s)" in line
    line = _one_line_error(["fight", "--physics", "--graph", tmp_path / "g.igz", "--seconds", "5", "--swap-a",
                            "30:outboxer", "--out", tmp_path / "p"], capsys)
    assert "beyond the bout's end" in line
    line = _one_line_error(["fight", "--graph", tmp_path / "g.igz", "--seconds", "5", "--swap-a", "2:boxer"], capsys)
    assert "boxer: unknown style" in line and "balanced, infighter, outboxer" in line
    line = _one_line_error(["fight", "--graph", tmp_path / "missing.igz", "--out", tmp_path / "k"], capsys)
    assert "missing.igz" in line and "no such file" in line
    (tmp_path / "empty").mkdir()
    line = _one_line_error(["mocap", "inspect", tmp_path / "empty"], capsys)
    assert "no .bvh or .amc files found" in line
    line = _one_line_error(["mocap", "inspect", tmp_path / "nope"], capsys)
    assert "no such file or folder" in line


@pytest.mark.realdata
def test_unknown_styles_are_answered_in_one_line_listing_the_presets(tiny_graph_file, tmp_path, capsys):
    g = str(tiny_graph_file)
    for argv in (["fight", "--graph", g, "--a", "boxer", "--seconds", "1", "--out", tmp_path / "k"],
                 ["fight", "--graph", g, "--b", "boxer", "--seconds", "1", "--out", tmp_path / "k"],
                 ["policy", "--graph", g, "--style", "boxer", "--depth", "1", "--repeat", "1"],
                 ["evaluate", "--graph", g, "--style", "boxer", "--out", tmp_path / "e"],
                 ["train-rl", "--graph", g, "--style", "boxer", "--out", tmp_path / "r.pt"],
                 ["fight", "--physics", "--graph", g, "--a", "boxer", "--seconds", "1", "--out", tmp_path / "p"]):
        line = _one_line_error(argv, capsys)
        assert "boxer: unknown style: not a preset (balanced, infighter, outboxer)" in line, line
    line = _one_line_error(["fight", "--graph", g, "--a", "styles/mine.toml", "--seconds", "1", "--out", tmp_path / "k"],
                           capsys)
    assert "a style file path was given" in line and "balanced, infighter, outboxer" in line
    line = _one_line_error(["evaluate", "--graph", g, "--opponents", "human,chuck", "--out", tmp_path / "e"], capsys)
    assert "unknown opponent 'chuck'" in line


def test_no_video_is_a_physics_option(tmp_path, capsys):
    """``--no-video`` parses for physics bouts (the IGRAPH_FIGHT_VIDEO variable stays the default)
    and is refused on kinematic bouts."""
    args = build_parser().parse_args(["fight", "--physics", "--graph", "g.igz", "--no-video"])
    assert args.video is False and args.physics
    assert build_parser().parse_args(["fight", "--graph", "g.igz"]).video is None
    line = _one_line_error(["fight", "--graph", tmp_path / "g.igz", "--no-video"], capsys)
    assert "physics bouts only" in line


def test_a_user_error_shows_its_traceback_on_request(tmp_path, monkeypatch):
    from igraph_fight.cli import TRACEBACK_ENV
    monkeypatch.setenv(TRACEBACK_ENV, "1")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="no .bvh or .amc files found"):
        main(["mocap", "inspect", str(tmp_path / "empty")])


def test_style_bouts_check_their_arguments_before_reading_the_graph(tmp_path):
    from igraph_fight.style_bout import run_style_bout
    g = tmp_path / "missing.igz"
    for kw, text in (({"seconds": -5.0}, "seconds must be a finite number > 0"),
                     ({"seconds": float("nan")}, "seconds must be a finite number > 0"),
                     ({"seed": -1}, "seed must be an integer >= 0"),
                     ({"seconds": 5.0, "swap_a": (30.0, "outboxer")}, r"swap time must lie in \[0, 5\)"),
                     ({"swap_a": (1.0, "boxer")}, "boxer: unknown style")):
        with pytest.raises(ValueError, match=text):
            run_style_bout(g, "infighter", "outboxer", **kw)
