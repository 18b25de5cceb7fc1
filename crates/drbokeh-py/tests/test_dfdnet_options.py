"""drbokeh.dfdnet's command line: run names, the table's and --quick's settings, named
protocols, --min-blur, the shared data cache and its one-line errors, and help that teaches."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

torch = pytest.importorskip("torch")


def test_run_names_round_trip():
    from drbokeh.dfdnet.train import TABLE_RUNS, parse_run

    for spec in TABLE_RUNS:
        assert parse_run(spec.name) == spec
    assert parse_run("physical-hssim-none").highlights == "none"
    with pytest.raises(ValueError, match="unknown run"):
        parse_run("physical-hssim-bright")
    ft = parse_run("physical5-hssim-from-aperture-hssim")
    assert (ft.layer, ft.loss, ft.start) == ("physical5", "hssim", parse_run("aperture-hssim"))
    assert ft.name == "physical5-hssim-from-aperture-hssim" and parse_run(ft.name) == ft
    for bad, why in (("supervised-from-aperture-hssim", "supervised"), ("physical5-hssim-from-supervised", "supervised"),
                     ("physical5-hssim-from-aperture-hssim-from-gausspsf-hssim", "another fine-tune"),
                     ("physical5-hssim-from-aperture", "unknown run")):
        with pytest.raises(ValueError, match=why):
            parse_run(bad)


def test_a_finetune_takes_its_own_steps_and_rate_and_needs_its_start(tmp_path, capsys):
    """``RUN-from-START`` trains ``--finetune-steps`` at ``--finetune-lr`` (the rest of the
    configuration as given); ``train`` refuses one whose start is neither trained in --out nor
    among the runs, in one line, before any tracing."""
    from drbokeh.dfdnet.__main__ import _cfg, main, parse_args
    from drbokeh.dfdnet.train import parse_run

    cfg = _cfg(parse_args(["train", "--out", "o", "--steps", "300", "--lr", "0.004",
                           "--finetune-steps", "40", "--finetune-lr", "0.0005"]))
    run = parse_run("physical5-hssim-from-aperture-hssim").config(cfg)
    assert (run.steps, run.lr, run.finetune_steps) == (40, 0.0005, 40)
    assert (parse_run("aperture-hssim").config(cfg).steps, parse_run("aperture-hssim").config(cfg).lr) == (300, 0.004)
    for bad in (["--finetune-steps", "0"], ["--finetune-lr", "-1"]):
        with pytest.raises(SystemExit):
            parse_args(["train", "--out", "o", *bad])
    capsys.readouterr()
    out, data = tmp_path / "o", tmp_path / "data"
    with pytest.raises(SystemExit) as e:
        main(["train", "--out", str(out), "--data", str(data), "--runs", "physical5-hssim-from-aperture-hssim"])
    msg = str(e.value)
    assert "starts from aperture-hssim, which is neither trained in" in msg and "\n" not in msg
    assert not data.exists() and not out.exists()  # nothing traced, nothing written


def test_unset_options_take_the_table_protocol_or_quick_settings():
    """The table's defaults (session 11's protocol: whole images, batch 2, 1500 steps,
    the far start, textured backgrounds); --quick keeps its own small settings; what the
    user gives wins; --init-disparity takes a disparity in (0, 1) or 'pytorch'."""
    from drbokeh.dfdnet.__main__ import _cfg, parse_args

    a = parse_args(["reproduce", "--out", "o"])
    cfg = _cfg(a)
    assert (cfg.steps, cfg.batch, cfg.crop, cfg.init_disparity) == (1500, 2, 128, 0.05)
    assert (a.size, a.background_detail) == (128, 1.0)
    q = parse_args(["train", "--quick", "--out", "o"])
    assert (q.size, q.steps, q.batch, q.crop, q.init_disparity, q.background_detail) == (64, 40, 4, 64, None, 0.0)
    b = parse_args(["train", "--out", "o", "--size", "192", "--crop", "96", "--init-disparity", "pytorch",
                    "--background-detail", "0"])
    cfg = _cfg(b)
    assert (cfg.crop, cfg.init_disparity, b.background_detail) == (96, None, 0.0)
    assert parse_args(["eval", "--out", "o", "--size", "192"]).crop == 192
    for bad in ("1.5", "0", "far"):
        with pytest.raises(SystemExit):
            parse_args(["train", "--out", "o", "--init-disparity", bad])


def test_a_named_protocol_is_the_long_command_line_and_given_options_win():
    """``--protocol session29`` gives exactly the settings of the long command line that
    docs/dfdnet.md ran for its current table (session 30's run24.sh); an option given
    beside it wins; session12 is the options' own defaults; --quick and an unknown name
    are refused."""
    from drbokeh.dfdnet.__main__ import _cfg, _runs, parse_args

    long = ["reproduce", "--data", "D4s", "--perspective", "--train-scenes", "960", "--val-scenes", "64",
            "--test-scenes", "128", "--min-blur", "3", "--batch", "4", "--inputs", "aif", "--init-disparity", "0.15",
            "--focus-prior", "4", "--focus-prior-radius", "1", "--seed", "24", "--jobs", "2", "--out", "R24",
            "--runs", "physical5-hssim,physical5-ssim,physical5-l1g,paper5-hssim,aperture-hssim,gausspsf-hssim,"
            "supervised"]
    short = parse_args(["reproduce", "--protocol", "session29", "--data", "D4s", "--seed", "24", "--out", "R24"])
    full = parse_args(long)
    assert {**vars(short), "protocol": None} == {**vars(full), "protocol": None}
    assert _cfg(short) == _cfg(full) and _runs(short) == _runs(full)
    assert (short.protocol, full.protocol) == ("session29", "session12")
    # what is given wins, in any order
    wider = parse_args(["eval", "--test-scenes", "512", "--protocol", "session29", "--out", "X", "--min-blur", "2"])
    assert (wider.test_scenes, wider.min_blur, wider.train_scenes, wider.perspective) == (512, 2.0, 960, True)
    assert vars(parse_args(["train", "--protocol", "session12", "--out", "o"])) == {
        **vars(parse_args(["train", "--out", "o"])), "protocol": "session12"}
    for bad in (["train", "--quick", "--protocol", "session29", "--out", "o"],
                ["reproduce", "--protocol", "session30", "--out", "o"]):
        with pytest.raises(SystemExit):
            parse_args(bad)


def test_min_blur_keeps_the_scenes_with_enough_blur_in_every_split():
    """--min-blur leaves out, in every split, the scenes whose largest blur K is below it
    (their arrays and names together); 0 keeps all; a split left empty, a negative or a
    non-finite threshold is an error."""
    from drbokeh.dfdnet.data import Split, with_min_blur

    def split(blurs):
        n = len(blurs)
        return Split(np.arange(n * 3 * 4, dtype=np.float32).reshape(n, 3, 2, 2), np.zeros((n, 3, 2, 2), np.float32),
                     np.zeros((n, 1, 2, 2), np.float32), np.zeros(n, np.float32), np.array(blurs, np.float32),
                     np.ones(n), np.ones(n), [f"s{i}" for i in range(n)])

    splits = {"train": split([1.0, 3.0, 9.0, 2.9]), "test": split([3.0, 1.5])}
    kept = with_min_blur(splits, 3.0)
    assert kept["train"].names == ["s1", "s2"] and kept["test"].names == ["s0"]
    assert np.array_equal(kept["train"].aif, splits["train"].aif[[1, 2]])
    assert np.array_equal(kept["train"].blur, [3.0, 9.0])
    assert [len(v) for v in with_min_blur(splits, 0.0).values()] == [4, 2]
    with pytest.raises(ValueError, match="no test scene"):
        with_min_blur(splits, 5.0)
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="minimum blur"):
            with_min_blur(splits, bad)
    # A cache traced with a threshold serves that threshold or more, never less.
    traced = {"train": split([3.0, 9.0])}
    traced["train"].traced_min_blur = 3.0
    assert with_min_blur(traced, 4.0)["train"].names == ["s1"]
    assert with_min_blur(traced, 4.0)["train"].traced_min_blur == 3.0
    for less in (0.0, 2.5):
        with pytest.raises(ValueError, match=r"holds only scenes with K >= 3.0 px"):
            with_min_blur(traced, less)
    from drbokeh.dfdnet.__main__ import parse_args

    assert parse_args(["train", "--out", "o"]).min_blur == 0.0
    assert parse_args(["eval", "--out", "o", "--min-blur", "3"]).min_blur == 3.0
    for bad in ("-1", "nan", "inf", "three"):
        with pytest.raises(SystemExit):
            parse_args(["train", "--out", "o", "--min-blur", bad])


def test_data_cache_is_shared_safely_and_a_damaged_one_is_a_one_line_error(tmp_path):
    """The cache record (``splits.json``) is written only when it changes, so processes
    sharing ``--data`` (training and eval side by side) never read it half-written; a
    damaged record or cached split is a ValueError naming the file (at the command line,
    one line, exit status not 0), before any tracing."""
    from drbokeh.dfdnet.__main__ import main
    from drbokeh.dfdnet.data import Split, SplitSpec, _save, prepare

    spec = SplitSpec("train", 1711, 2, 16, 4, "far")
    n = 2
    split = Split(np.zeros((n, 3, 16, 16), np.float32), np.zeros((n, 3, 16, 16), np.float32),
                  np.zeros((n, 1, 16, 16), np.float32), np.zeros(n, np.float32), np.full(n, 3.0, np.float32),
                  np.ones(n), np.ones(n), ["a", "b"])
    cache = tmp_path / "cache"
    cache.mkdir()
    _save(split, cache / "train.npz")
    loaded = prepare(cache, [spec], cli="/nonexistent/drbokeh")["train"]  # cached: never traced
    assert loaded.names == ["a", "b"] and np.array_equal(loaded.blur, split.blur)
    record = cache / "splits.json"
    stamp = record.stat().st_mtime_ns
    os.utime(record, ns=(stamp - 10**9, stamp - 10**9))
    prepare(cache, [spec], cli="/nonexistent/drbokeh")
    assert record.stat().st_mtime_ns == stamp - 10**9, "an unchanged record was written again"
    assert sorted(p.name for p in cache.iterdir()) == ["splits.json", "train.npz"], "a temporary file was left"
    # only: the splits named, the others neither traced nor loaded (the missing val would be
    # traced, and fail with this CLI); the record holds every split's spec
    val, two = SplitSpec("val", 1712, 2, 16, 4, "far"), tmp_path / "two"
    two.mkdir()
    _save(split, two / "train.npz")
    assert list(prepare(two, [spec, val], cli="/nonexistent/drbokeh", only=("train",))) == ["train"]
    assert [r["name"] for r in json.loads((two / "splits.json").read_text())] == ["train", "val"]
    with pytest.raises(ValueError, match="no split named test"):
        prepare(two, [spec, val], cli="/nonexistent/drbokeh", only=("test",))
    with pytest.raises(FileNotFoundError):  # val is missing: traced
        prepare(two, [spec, val], cli="/nonexistent/drbokeh")

    good = (cache / "train.npz").read_bytes()
    for damaged in (good[: len(good) // 2], b"not an npz"):
        (cache / "train.npz").write_bytes(damaged)
        with pytest.raises(ValueError, match="train.npz: not a cached split"):
            prepare(cache, [spec], cli="/nonexistent/drbokeh")
    (tmp_path / "o" / "physical-hssim").mkdir(parents=True)
    for name in ("model.pt", "log.json"):  # a run for eval (never read: the data fails first)
        (tmp_path / "o" / "physical-hssim" / name).write_text("{}")
    for bad in ("", "{", "7", '["x"]'):
        record.write_text(bad)
        with pytest.raises(ValueError, match="splits.json: not a record of splits"):
            prepare(cache, [spec], cli="/nonexistent/drbokeh")
        with pytest.raises(SystemExit) as exit_info:
            main(["eval", "--data", str(cache), "--out", str(tmp_path / "o"), "--runs", "physical-hssim",
                  "--drbokeh", "/nonexistent/drbokeh"])
        message = str(exit_info.value.code)
        assert message.startswith("--data: ") and "splits.json" in message and "\n" not in message


@pytest.mark.parametrize("cmd", [[], ["train"], ["eval"], ["reproduce"], ["table"]])
def test_every_help_teaches_with_examples(cmd, capsys):
    """`--help` of the program and of each command prints its description and examples
    that name that command (the CLI's rule: help that teaches)."""
    from drbokeh.dfdnet.__main__ import parse_args

    with pytest.raises(SystemExit) as exit_info:
        parse_args(cmd + ["--help"])
    assert exit_info.value.code == 0
    text = capsys.readouterr().out
    assert "examples:" in text
    example_lines = [ln for ln in text.splitlines() if ln.strip().startswith("python -m drbokeh.dfdnet ")]
    assert len(example_lines) >= 2
    if cmd:
        assert all(f"drbokeh.dfdnet {cmd[0]} " in ln for ln in example_lines)


def test_training_progress_says_how_long_is_left():
    """The progress line's estimate: the recent seconds per step times the steps left, in
    minutes from one minute up, nothing after the last step."""
    from drbokeh.dfdnet.train import time_left

    assert time_left(1.6, 1200) == ", about 32 min left"
    assert time_left(0.5, 100) == ", about 50 s left"
    assert time_left(2.0, 30) == ", about 1 min left"
    assert time_left(1.6, 0) == ""


@pytest.mark.parametrize("option, bad", [
    ("--steps", "-5"), ("--steps", "0"), ("--batch", "0"), ("--base", "0"), ("--size", "-128"), ("--spp", "0"),
    ("--train-scenes", "0"), ("--test-scenes", "ten"), ("--threads", "0"), ("--jobs", "0"), ("--crop", "0"),
    ("--lr", "0"), ("--lr", "nan"), ("--lr", "-1e-3"), ("--focus-prior", "-1"), ("--focus-prior", "inf"),
])
def test_a_number_out_of_range_is_refused_in_one_line(option, bad, capsys):
    """Counts below 1, a learning rate that is not > 0 and a negative or infinite weight are
    refused when the command line is read (before tracing or training: `--steps -5` once
    "trained" every run for no step and wrote NaN into its log), naming the option."""
    from drbokeh.dfdnet.__main__ import parse_args

    with pytest.raises(SystemExit) as e:
        parse_args(["train", "--out", "o", f"{option}={bad}"])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert option in err and repr(bad) in err, err


def test_eval_without_a_trained_run_says_so_before_tracing(tmp_path):
    """``eval --out DIR`` where DIR holds none of the runs asked for (a run's weights without
    its log.json do not count): one line naming DIR, exit status not 0, nothing traced (the
    CLI given does not exist) and nothing written."""
    from drbokeh.dfdnet.__main__ import main

    out, data = tmp_path / "nothing", tmp_path / "data"
    (out / "physical-hssim").mkdir(parents=True)
    (out / "physical-hssim" / "model.pt").write_bytes(b"")  # weights without their log.json: not trained
    with pytest.raises(SystemExit) as e:
        main(["eval", "--out", str(out), "--data", str(data), "--runs", "physical-hssim,aperture-hssim",
              "--drbokeh", "/nonexistent/drbokeh"])
    message = str(e.value.code)
    assert message.startswith("eval: no run of physical-hssim, aperture-hssim is trained in") and str(out) in message
    assert "\n" not in message
    assert sorted(p.name for p in out.rglob("*")) == ["model.pt", "physical-hssim"] and not data.exists()


@pytest.mark.parametrize("cmd", [["train", "--runs", "supervised"], ["train", "--quick"], ["eval"], ["reproduce"]])
def test_a_file_where_a_directory_belongs_is_refused_in_one_line(cmd, tmp_path):
    """--out or --data naming an existing file: one line naming the option and the path, the
    file left as it was, nothing traced (the CLI given does not exist)."""
    from drbokeh.dfdnet.__main__ import main

    f = tmp_path / "a-file"
    f.write_bytes(b"keep me")
    for option, more in (("--out", []), ("--data", ["--out", str(tmp_path / "o")])):
        with pytest.raises(SystemExit) as e:
            main([*cmd, option, str(f), *more, "--drbokeh", "/nonexistent/drbokeh"])
        assert str(e.value.code) == f"{option} {f}: exists and is not a directory"
        assert f.read_bytes() == b"keep me" and not (tmp_path / "o").exists()
    with pytest.raises(SystemExit) as e:
        main(["table", str(tmp_path / "x"), str(tmp_path / "y"), "-o", str(f)])
    assert str(e.value.code) == f"--out {f}: exists and is not a directory"
