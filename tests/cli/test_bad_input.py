"""Bad command lines: each gets exit status 2 and one line on stderr naming the argument or file,
never a traceback, and no work is done or file written on its behalf.

The table holds one row per bad invocation (``{tmp}`` and the other placeholders are files the
fixture makes). Rows run in-process through ``biped_opt.cli.main.main``: argparse's own errors
arrive as SystemExit(2), the commands' as a return value of 2. Every check of an output path
happens before any simulation, node or file is started, so no row runs longer than the parsing.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from biped_opt.cli.main import main
from biped_opt.record import SweepWriter

MCAP_MAGIC = b"\x89MCAP0\r\n"
MANEUVERS = "--maneuver: maneuver must be one of touchdown, liftoff; got"
LONG = "x" * 100_000

# (argv, fragment the one line must contain)
CASES: list[tuple[list[str], str]] = [
    # -- top level -----------------------------------------------------------------------
    ([], "the following arguments are required: command"),
    (["bogus"], "invalid choice: 'bogus'"),
    (["--theta0", "0"], "invalid choice: '0'"),
    (["node", "bogus"], "argument name: invalid choice: 'bogus'"),
    # -- simulate ------------------------------------------------------------------------
    (["simulate"], "--maneuver is required"),
    (["simulate", "--maneuver", "touchdown"], "--theta0 is required"),
    (["simulate", "--maneuver", "jump", "--theta0", "0"], f"{MANEUVERS} 'jump'"),
    (["simulate", "--maneuver", "", "--theta0", "0"], "--maneuver"),
    (["simulate", "--maneuver", LONG, "--theta0", "0"], "(100000 characters)"),
    (["simulate", "--maneuver", "touch\udcffdown", "--theta0", "0"], "--maneuver"),
    (["simulate", "--maneuver", "touchdown", "--theta0", "nan"], "--theta0 must be finite"),
    (["simulate", "--maneuver", "touchdown", "--theta0", "inf"], "--theta0 must be finite"),
    (["simulate", "--maneuver", "touchdown", "--theta0", "-inf"], "--theta0 must be finite"),
    (["simulate", "--maneuver", "touchdown", "--theta0", "1e400"], "--theta0 must be finite"),
    (["simulate", "--maneuver", "touchdown", "--theta0", "abc"], "--theta0 must be a number"),
    (["simulate", "--maneuver", "touchdown", "--theta0", ""], "--theta0 must be a number"),
    (["simulate", "--maneuver", "touchdown", "--theta0", "0x1p-3"], "--theta0 must be a number"),
    (["simulate", "--maneuver", "touchdown", "--theta0", "3.0"], "--theta0:"),
    (["simulate", "--maneuver", "touchdown", "--theta0", "-3"], "--theta0:"),
    (["simulate", "--maneuver", "liftoff", "--theta0", "-1e3"], "--theta0:"),
    (["simulate", "--maneuver", "touchdown", "--theta0"], "--theta0: expected one argument"),
    (["simulate", "--maneuver", "touchdown", "--theta0", "0", "--u1", "nan"], "--u1 must be"),
    (["simulate", "--maneuver", "touchdown", "--theta0", "0", "--u2", "x"], "--u2 must be"),
    (["simulate", "--maneuver", "touchdown", "--theta0", "0", "--u12", "-inf"], "--u12 must be"),
    (["simulate", "--maneuver", "touchdown", "--theta0", "0", "--u3", "1"],
     "unrecognized arguments: --u3"),
    (["simulate", "--maneuver", "touchdown", "--theta0", "0", "extra"],
     "unrecognized arguments: extra"),
    # -- optimise ------------------------------------------------------------------------
    (["optimise", "--maneuver", "touchdown"], "--theta0 is required"),
    (["optimise", "--maneuver", "hop", "--theta0", "0"], f"{MANEUVERS} 'hop'"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "nan"], "--theta0 must be finite"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "2"], "--theta0:"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "0", "--alpha", "u1=1e308"],
     "--alpha: alphas[u1] = 1e+308"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "0", "--alpha", "u3=1"],
     "--alpha must look like NAME=VALUE"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "0", "--alpha", "u1"],
     "--alpha must look like NAME=VALUE"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "0", "--alpha", "u1=abc"],
     "--alpha u1: 'abc' is not a number"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "0", "--alpha", "u1=nan"],
     "--alpha u1: must be finite"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "0", "--alpha", "u1=-1"],
     "--alpha: alphas[u1] must be non-negative"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "0", "--alpha", "u12=1"],
     "--alpha: 'u12' is not a decision input"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "0", "--bounds", "u1=1,0"],
     "--bounds: bounds[u1] must have lower < upper"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "0", "--bounds", "u1=1"],
     "--bounds u1: expected LO,HI"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "0", "--bounds", "u1=a,b"],
     "--bounds u1: 'a' is not a number"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "0", "--bounds", "u1=0,inf"],
     "--bounds u1: must be finite"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "0", "--bounds", "u1=-1e200,1e200"],
     "--bounds: alphas[u1]"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "0", "--fixed", "u1=1"],
     "--fixed: u1 is a decision"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "0", "--fixed", "u12=nan"],
     "--fixed u12: must be finite"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "0", "--theta-star", "1e300"],
     "--theta-star"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "0", "--theta-star", "nan"],
     "--theta-star must be finite"),
    (["optimise", "--maneuver", "touchdown", "--theta0", "0", "--variant"],
     "--variant: only the liftoff maneuver"),
    # -- sweep ---------------------------------------------------------------------------
    (["sweep", "--maneuver", "touchdown", "--num", "1"], "--num must be between 2 and 1000000"),
    (["sweep", "--maneuver", "touchdown", "--num", "0"], "--num must be between 2 and 1000000"),
    (["sweep", "--maneuver", "touchdown", "--num", "-3"], "--num must be between 2 and 1000000"),
    (["sweep", "--maneuver", "touchdown", "--num", "abc"], "--num must be an integer"),
    (["sweep", "--maneuver", "touchdown", "--num", "2.5"], "--num must be an integer"),
    (["sweep", "--maneuver", "touchdown", "--theta0-min", "0.1", "--theta0-max", "-0.1"],
     "--theta0-min must be below --theta0-max"),
    (["sweep", "--maneuver", "touchdown", "--theta0-min", "0.1", "--theta0-max", "0.1"],
     "--theta0-min must be below --theta0-max"),
    (["sweep", "--maneuver", "touchdown", "--theta0-min", "nan"], "--theta0-min must be finite"),
    (["sweep", "--maneuver", "touchdown", "--theta0-max", "5"], "--theta0-max:"),
    (["sweep", "--maneuver", "touchdown", "--theta0-min", "-5e0"], "--theta0-min:"),
    (["sweep", "--maneuver", "touchdown", "--out", "{dir}"], "--out: '{dir}' is a directory"),
    (["sweep", "--maneuver", "touchdown", "--out", "{tmp}/missing/s.json"],
     "--out: directory '{tmp}/missing' does not exist"),
    (["sweep", "--maneuver", "touchdown", "--out", "{text}/s.json"],
     "--out: directory '{text}' does not exist"),
    (["sweep", "--maneuver", "touchdown", "--optimal", "--alpha", "u1=1e308"], "--alpha:"),
    (["sweep", "--maneuver", "touchdown", "--u1", "nan"], "--u1 must be finite"),
    (["sweep", "--maneuver", "liftoff", "--variant", "--bounds", "u12=0,1"],
     "--bounds: 'u12' is not a decision input"),
    # -- nonsmooth -----------------------------------------------------------------------
    (["nonsmooth", "--maneuver", "touchdown", "--num", "1"], "--num must be between 2 and 1000000"),
    (["nonsmooth", "--maneuver", "touchdown", "--theta0-min", "1e-3", "--theta0-max", "-1e-3"],
     "--theta0-min must be below --theta0-max"),
    (["nonsmooth", "--maneuver", "x"], f"{MANEUVERS} 'x'"),
    (["nonsmooth", "--maneuver", "touchdown", "--variant"], "--variant: only the liftoff"),
    (["nonsmooth", "--maneuver", "touchdown", "--optimal", "--bounds", "u1=2,1"],
     "--bounds: bounds[u1] must have lower < upper"),
    (["nonsmooth", "--maneuver", "touchdown", "--json", "--num", "x"], "--num must be"),
    # -- figures -------------------------------------------------------------------------
    (["figures", "--out", "{text}"], "--out: '{text}' exists and is not a directory"),
    (["figures", "--out", "{text}/sub"], "--out: cannot create directory '{text}/sub'"),
    (["figures", "--out", "/proc/biped_opt_figures"], "--out: cannot create directory"),
    (["figures", "--fixed-num", "4"], "--fixed-num must be between 5 and 1000000"),
    (["figures", "--fixed-num", "x"], "--fixed-num must be an integer"),
    (["figures", "--optimal-num", "0"], "--optimal-num must be between 5 and 1000000"),
    (["figures", "--optimal-num", "-1"], "--optimal-num must be between 5 and 1000000"),
    # -- demo ----------------------------------------------------------------------------
    (["demo", "--out", "{text}"], "--out: '{text}' exists and is not a directory"),
    (["demo", "--out", "{text}/sub"], "--out: cannot create directory '{text}/sub'"),
    (["demo", "--out", "/proc/biped_opt_demo"], "--out: cannot create directory"),
    # -- record --------------------------------------------------------------------------
    (["record"], "the following arguments are required"),
    (["record", "--maneuver", "touchdown", "--theta0-min", "-0.1", "--theta0-max", "0.1",
      "--num", "3", "--out", "{text}"], "--out: '{text}' exists"),
    (["record", "--maneuver", "touchdown", "--theta0-min", "-0.1", "--theta0-max", "0.1",
      "--num", "3", "--out", "{mcap}"], "--out: '{mcap}' exists"),
    (["record", "--maneuver", "touchdown", "--theta0-min", "-0.1", "--theta0-max", "0.1",
      "--num", "3", "--out", "{dir}"], "--out: '{dir}' is a directory"),
    (["record", "--maneuver", "touchdown", "--theta0-min", "-0.1", "--theta0-max", "0.1",
      "--num", "3", "--out", "{tmp}/missing/r.mcap"],
     "--out: directory '{tmp}/missing' does not exist"),
    (["record", "--maneuver", "touchdown", "--theta0-min", "-0.1", "--theta0-max", "0.1",
      "--num", "3", "--out", "{text}/r.mcap"], "--out: directory '{text}' does not exist"),
    (["record", "--maneuver", "touchdown", "--theta0-min", "-0.1", "--theta0-max", "0.1",
      "--num", "1", "--out", "{tmp}/r.mcap"], "--num must be between 2 and 100000"),
    (["record", "--maneuver", "touchdown", "--theta0-min", "-0.1", "--theta0-max", "0.1",
      "--num", "100001", "--out", "{tmp}/r.mcap"], "--num must be between 2 and 100000"),
    (["record", "--maneuver", "touchdown", "--theta0-min", "-0.1", "--theta0-max", "0.1",
      "--num", "x", "--out", "{tmp}/r.mcap"], "--num must be an integer"),
    (["record", "--maneuver", "walk", "--theta0-min", "-0.1", "--theta0-max", "0.1",
      "--num", "3", "--out", "{tmp}/r.mcap"], "got 'walk'"),
    (["record", "--maneuver", "touchdown", "--theta0-min", "0.1", "--theta0-max", "-0.1",
      "--num", "3", "--out", "{tmp}/r.mcap"], "theta0_min must be below theta0_max"),
    (["record", "--maneuver", "touchdown", "--theta0-min", "nan", "--theta0-max", "0.1",
      "--num", "3", "--out", "{tmp}/r.mcap"], "--theta0-min must be finite"),
    (["record", "--maneuver", "touchdown", "--theta0-min", "-1e-6", "--theta0-max", "1e-6",
      "--num", "3", "--out", "{tmp}/r.mcap", "--params-file", "{tmp}/none.yaml"],
     "--params-file: no such file '{tmp}/none.yaml'"),
    (["record", "--maneuver", "touchdown", "--theta0-min", "-0.1", "--theta0-max", "0.1",
      "--num", "3", "--out", "{tmp}/r.mcap", "--params-file", "{dir}"],
     "--params-file: '{dir}' is not a file"),
    # -- launch --------------------------------------------------------------------------
    (["launch", "--params-file", "{tmp}/none.yaml"], "--params-file: no such file"),
    (["launch", "--params-file", "{dir}"], "--params-file: '{dir}' is not a file"),
    # -- report --------------------------------------------------------------------------
    (["report", "--out", "{tmp}/rep"], "the following arguments are required: FILE"),
    (["report", "{mcap}"], "the following arguments are required: --out"),
    (["report", "{tmp}/none.mcap", "--out", "{tmp}/rep"], "no such recording"),
    (["report", "{text}", "--out", "{tmp}/rep"], "{text}: not an MCAP file"),
    (["report", "{empty}", "--out", "{tmp}/rep"], "{empty}: not an MCAP file"),
    (["report", "{dir}", "--out", "{tmp}/rep"], "{dir}"),
    (["report", "{mcap}", "--out", "{text}"], "--out: '{text}' exists and is not a directory"),
    (["report", "{mcap}", "--out", "{text}/sub/rep"],
     "--out: cannot create directory '{text}/sub/rep': '{text}' is not a directory"),
    # -- info ----------------------------------------------------------------------------
    (["info"], "the following arguments are required: file"),
    (["info", "{tmp}/none.mcap"], "no such recording"),
    (["info", "{text}"], "{text}: not an MCAP file"),
    (["info", "{empty}"], "{empty}: not an MCAP file"),
    (["info", "{magic}"], "{magic}"),
    (["info", "{dir}"], "{dir}"),
    (["info", "{mcap}", "--to-rosbag2", "{text}"],
     "--to-rosbag2: '{text}' exists and is not a directory"),
    (["info", "{mcap}", "--to-rosbag2", "{full}"], "--to-rosbag2: directory '{full}' is not empty"),
    (["info", "{mcap}", "--to-rosbag2", "{tmp}/missing/bag"],
     "--to-rosbag2: directory '{tmp}/missing' does not exist"),
    (["info", "{text}", "--json"], "not an MCAP file"),
    # -- replay --------------------------------------------------------------------------
    (["replay", "{mcap}", "--domain-id", "300"], "--domain-id must be between 0 and 232"),
    (["replay", "{mcap}", "--domain-id", "-1"], "--domain-id must be between 0 and 232"),
    (["replay", "{mcap}", "--domain-id", "x"], "--domain-id must be an integer"),
    (["replay", "{mcap}", "--rate", "0"], "--rate must be between 0.001 and 1000"),
    (["replay", "{mcap}", "--rate", "-1"], "--rate must be between 0.001 and 1000"),
    (["replay", "{mcap}", "--rate", "nan"], "--rate must be finite"),
    (["replay", "{mcap}", "--delay", "-0.5"], "--delay must be between 0 and 3600"),
    (["replay", "{tmp}/none.mcap"], "no such recording"),
    (["replay", "{text}"], "{text}: not an MCAP file"),
    (["replay", "{empty}"], "{empty}: not an MCAP file"),
    # -- bench ---------------------------------------------------------------------------
    (["bench", "--cases", "1"], "--cases must be between 2 and 1000000"),
    (["bench", "--cases", "many"], "--cases must be an integer"),
    (["bench", "--cases", "10000000"], "--cases must be between 2 and 1000000, got 10000000"),
    (["bench", "--seed", "-1"], "--seed must be between 0 and 4294967295, got -1"),
    (["bench", "--seed", "1.5"], "--seed must be an integer, got '1.5'"),
    # -- every numeric option has a stated range: a typo never starts an unbounded run ----
    (["sweep", "--maneuver", "touchdown", "--num", "1000000000"],
     "--num must be between 2 and 1000000, got 1000000000"),
    (["sweep", "--maneuver", "touchdown", "--num", "1e9"], "--num must be an integer, got '1e9'"),
    (["sweep", "--maneuver", "touchdown", "--num", "9" * 5000],
     "--num must be an integer, got '99999999999999999999'... (5000 characters)"),
    (["nonsmooth", "--maneuver", "touchdown", "--num", "1e10"], "--num must be an integer"),
    (["nonsmooth", "--maneuver", "touchdown", "--num", "10000000000"],
     "--num must be between 2 and 1000000"),
    (["figures", "--fixed-num", "2000000"], "--fixed-num must be between 5 and 1000000"),
    (["figures", "--system", "rocking_bar", "--num", "2000000"],
     "--num must be between 5 and 1000000"),
    (["gradients", "--seed", "-1"], "--seed must be between 0 and 4294967295, got -1"),
    (["gradients", "--seed", "4294967296"], "--seed must be between 0 and 4294967295"),
    (["gradients", "--seed", "x"], "--seed must be an integer, got 'x'"),
    (["gradients", "--samples", "1"], "--samples must be between 2 and 200000, got 1"),
    (["gradients", "--starts", "21"], "--starts must be between 1 and 20, got 21"),
    (["gradients", "--iterations", "0"], "--iterations must be between 1 and 1000"),
    (["gradients", "--quadrature", "nan"], "--quadrature must be an integer, got 'nan'"),
    (["gradients", "--problem", "touchdown", "--quadrature", "20001"],
     "a quadrature of 20001 points per axis over 2 decisions is 400040001 points, more than "
     "1000000"),
    (["report", "{text}", "--out", "{tmp}/r", "--jobs", "0"], "--jobs must be between 1 and 64"),
    (["pieces", "--seed", "-1"], "--seed must be between 0 and 4294967295"),
    (["pieces", "--rounds", "0"], "--rounds must be between 1 and 10"),
    (["pieces", "--rounds", "1000"], "--rounds must be between 1 and 10"),
    (["pieces", "--samples", "100000000"], "--samples must be between 2 and 1000000"),
    (["pieces", "--radius", "0.5"], "--radius must be at most 0.01, got '0.5'"),
    (["pieces", "--legs", "9"], "--legs must be between 1 and 4"),
    (["study", "{study}", "--out", "{tmp}/t.csv", "--workers", "0"],
     "--workers must be between 1 and 256"),
    (["study", "{study}", "--out", "{tmp}/t.csv", "--workers", "100000"],
     "--workers must be between 1 and 256"),
    (["study", "{study}", "--out", "{tmp}/t.csv", "--ros", "--item-timeout", "1e12"],
     "--item-timeout must be at most 86400"),
    (["replay", "{mcap}", "--rate", "1e-9"], "--rate must be between 0.001 and 1000"),
    (["replay", "{mcap}", "--rate", "1e9"], "--rate must be between 0.001 and 1000"),
    (["replay", "{mcap}", "--delay", "1e300"], "--delay must be between 0 and 3600"),
    # -- every output path is checked while parsing: before any work, nothing created -----
    # (root may write everywhere by os.access, /proc included: a file must really be creatable)
    (["study", "{study}", "--out", "/proc/x.csv"], "--out: directory '/proc' is not writable"),
    (["study", "{study}", "--out", "{tmp}/t.csv", "--mcap", "/proc/x.mcap"],
     "--mcap: directory '/proc' is not writable"),
    (["study", "{study}", "--out", "{dir}"], "--out: '{dir}' is a directory"),
    (["study", "{study}", "--out", "{tmp}/missing/t.csv"],
     "--out: directory '{tmp}/missing' does not exist"),
    (["study", "{study}", "--out", "{tmp}/t.csv", "--mcap", "{dir}"], "--mcap: '{dir}' is a "),
    (["study", "{study}", "--out", "{tmp}/t.csv", "--figures", "{text}"],
     "--figures: '{text}' exists and is not a directory"),
    (["study", "{study}", "--out", "{tmp}/t.csv", "--figures", "/proc/figs"],
     "--figures: cannot create directory '/proc/figs': '/proc' is not writable"),
    (["study", "{study}", "--out", "/proc/self/status"], "is not a study table"),
    (["gradients", "--figures", "{text}"], "--figures: '{text}' exists and is not a directory"),
    (["gradients", "--figures", "/proc/figs"], "--figures: cannot create directory '/proc/figs'"),
    (["gradients", "--figures", "{text}/sub"], "--figures: cannot create directory"),
    (["pieces", "--figure", "/proc/x.png"], "--figure: directory '/proc' is not writable"),
    (["pieces", "--figure", "{dir}"], "--figure: '{dir}' is a directory"),
    (["pieces", "--figure", "{tmp}/missing/p.png"],
     "--figure: directory '{tmp}/missing' does not exist"),
    (["record", "--maneuver", "touchdown", "--theta0-min", "-0.1", "--theta0-max", "0.1",
      "--num", "3", "--out", "/proc/r.mcap"], "--out: directory '/proc' is not writable"),
    (["record", "--maneuver", "touchdown", "--theta0-min", "-0.1", "--theta0-max", "0.1",
      "--num", "3", "--out", "/sys/r.mcap"], "--out: directory '/sys' is not writable"),
    (["info", "{mcap}", "--to-rosbag2", "/proc/bag"],
     "--to-rosbag2: directory '/proc' is not writable"),
    (["info", "{mcap}", "--to-rosbag2", "{mcap}"],
     "--to-rosbag2: '{mcap}' exists and is not a directory"),
    (["report", "{mcap}", "--out", "/proc/rep"],
     "--out: cannot create directory '/proc/rep': '/proc' is not writable"),
    (["sweep", "--maneuver", "touchdown", "--out", "/proc/s.json"],
     "--out: directory '/proc' is not writable"),
    (["sweep", "--maneuver", "touchdown", "--out", "{tmp}/" + "n" * 300],
     "characters): File name too long"),
    (["sweep", "--maneuver", "touchdown", "--out", "{tmp}/a\0b.json"],
     "--out: '{tmp}/a\\x00b.json': a file name holds no NUL byte"),
    (["study", "{study}", "--out", "{tmp}/t\0.csv"], "a file name holds no NUL byte"),
    (["report", "{mcap}", "--out", "{tmp}/r\0"], "a file name holds no NUL byte"),
    (["info", "{mcap}", "--to-rosbag2", "{tmp}/b\0"], "a file name holds no NUL byte"),
    (["sweep", "--maneuver", "touchdown", "--out", "/" + "d" * 100_000],
     "(100001 characters)"),
    (["figures", "--out", "/proc/f"], "--out: cannot create directory '/proc/f'"),
    (["demo", "--out", "/proc/d"], "--out: cannot create directory '/proc/d'"),
    (["launch", "--params-file", "/proc/none.yaml"], "--params-file: no such file"),
    (["report", "{mcap}", "--out", "{tmp}/" + "r" * 300], "characters): File name too long"),
    (["study", "{tmp}/none.yaml", "--out", "{tmp}/t.csv"], "{tmp}/none.yaml: no such study"),
    (["study", "{dir}", "--out", "{tmp}/t.csv"], "{dir}: no such study file"),
    # -- issue 34: files and values that once ended in a traceback or exit 0 ---------------
    (["study", "{latin}", "--out", "{tmp}/t.csv"], "{latin}: not UTF-8 text (byte 44"),
    (["study", "{bigseed}", "--out", "{tmp}/t.csv"],
     "{bigseed}: not valid YAML (ValueError: Exceeds the limit (4300 digits)"),
    (["study", "/dev/zero", "--out", "{tmp}/t.csv"],
     "/dev/zero: is a character device, not a regular file"),
    (["launch", "--params-file", "{badyaml}"],
     "cannot read parameter file {badyaml}: line 2, column 1: not valid YAML (expected ',' "
     "or ']', but got '<stream end>')"),
    (["launch", "--params-file", "{latin}"], "{latin}: not UTF-8 text"),
    (["simulate", "--system", "rocking_bar", "--maneuver", "drop", "--s", "99"],
     "--s: s = 99 is outside the valid range [-0.3, 0.3] of the drop maneuver of rocking_bar"),
    (["simulate", "--system", "rocking_bar", "--maneuver", "drop", "--s", "0.1", "--param",
      "m=-1"], "--param: rocking_bar: the parameters (m=-1) give a mass matrix that is not "
               "positive definite"),
    (["simulate", "--system", "rocking_bar", "--maneuver", "drop", "--s", "0.1", "--param",
      "gamma=1.5"], "--param: rocking_bar: the parameters (gamma=1.5) give a restitution of "
                    "1.5; it must be in [0, 1]"),
    (["animate", "--system", "rocking_bar", "--maneuver", "drop", "--s", "-5", "-o",
      "{tmp}/a.gif"], "--s: s = -5 is outside the valid range"),
    (["optimise", "--system", "rocking_bar", "--problem", "drop", "--s", "2"],
     "--s: s = 2 is outside the valid range"),
    (["simulate", "--system", "walker99", "--maneuver", "touchdown", "--s", "0"],
     "--system: walker99 has 99 constraints and 201 coordinates; the command line compiles "
     "at most 6 and 16, as the nodes do"),
    (["systems", "--check", "walker7"], "NAME: walker7 has 7 constraints and 17 coordinates"),
    (["systems", "walker99"], "add --large to compile it anyway"),
    (["animate", "--system", "walker99", "--maneuver", "touchdown", "-o", "{tmp}/a.gif"],
     "--system: walker99 has 99 constraints"),
    (["record", "--system", "walker99", "--maneuver", "touchdown", "--theta0-min", "-0.1",
      "--theta0-max", "0.1", "--num", "3", "--out", "{tmp}/r.mcap"],
     "--system: walker99 has 99 constraints"),
    (["sweep", "--system", "quadruped", "--maneuver", "trot"],
     "--system: quadruped has 4 constraints and 20 coordinates"),
    (["info", "/dev/zero"], "/dev/zero: is a character device, not a regular file"),
    (["report", "/dev/zero", "--out", "{tmp}/rep"], "/dev/zero: is a character device"),
]


@pytest.fixture(scope="module")
def places(tmp_path_factory) -> dict[str, str]:
    tmp = tmp_path_factory.mktemp("bad_input")
    (tmp / "notes.txt").write_text("these are notes, not a recording\n")
    (tmp / "empty.mcap").write_bytes(b"")
    (tmp / "magic.mcap").write_bytes(MCAP_MAGIC)
    (tmp / "dir").mkdir()
    (tmp / "full").mkdir()
    (tmp / "full" / "x").write_text("x")
    (tmp / "study.yaml").write_text("system: rocking_bar\nmaneuver: drop\n"
                                    "grid: {gamma: [0.5]}\nnum: 61\n")
    (tmp / "latin.yaml").write_bytes("system: rocking_bar\nmaneuver: drop\nname: caf\xe9\n"
                                     "grid: {gamma: [0.5]}\n".encode("latin-1"))
    (tmp / "bigseed.yaml").write_text("system: rocking_bar\nmaneuver: drop\ngrid: {gamma: "
                                      f"[0.5]}}\nseed: {'9' * 5001}\n")
    (tmp / "bad.yaml").write_text('{"a": [1, 2\n')
    with SweepWriter(tmp / "good.mcap", metadata={"maneuver": "touchdown"}) as w:
        w.write("/biped/contact_mode", {"header": {"stamp": {"sec": 0, "nanosec": 0},
                                                   "frame_id": "biped"}, "mode": 0}, 0)
    return {"tmp": str(tmp), "text": str(tmp / "notes.txt"), "empty": str(tmp / "empty.mcap"),
            "magic": str(tmp / "magic.mcap"), "dir": str(tmp / "dir"),
            "full": str(tmp / "full"), "mcap": str(tmp / "good.mcap"),
            "study": str(tmp / "study.yaml"), "latin": str(tmp / "latin.yaml"),
            "bigseed": str(tmp / "bigseed.yaml"), "badyaml": str(tmp / "bad.yaml")}


def _fill(text: str, places: dict[str, str]) -> str:
    for key, value in places.items():
        text = text.replace("{" + key + "}", value)
    return text


def _listing(root: Path) -> set[Path]:
    return set(root.rglob("*"))


def test_there_are_at_least_200_cases():
    assert len(CASES) >= 200


@pytest.mark.parametrize(("argv", "fragment"), CASES,
                         ids=[" ".join(a)[:60] or "(none)" for a, _ in CASES])
def test_bad_invocation_is_one_line_and_status_2(argv, fragment, places, capsys):
    tmp = Path(places["tmp"])
    before = _listing(tmp)
    argv = [_fill(a, places) for a in argv]
    try:
        status = main(argv)
    except SystemExit as exc:  # argparse's own errors
        status = exc.code
    out, err = capsys.readouterr()
    assert status == 2, (out, err)
    assert err.endswith("\n") and err.count("\n") == 1, err
    assert "Traceback" not in err and len(err) < 400, err
    assert _fill(fragment, places) in err, err
    assert out == ""
    assert _listing(tmp) == before  # nothing created, nothing left half-written


@pytest.mark.parametrize("value", ["-1e-6", "-1E-6", "-.5e-3", "-0.", "-0", "-0.1e+0"])
def test_negative_numbers_in_any_form_are_values(value, capsys):
    """argparse alone reads -1e-6 as an unknown option; near 0 is where the paper's kink and
    jump are, so every form float() accepts must reach the command as a value."""
    assert main(["simulate", "--maneuver", "touchdown", "--theta0", value, "--json"]) == 0
    assert f'"theta0": {float(value)!r}' in capsys.readouterr().out.replace("-0.0", "-0.0")


def test_json_output_is_strict_json(capsys):
    """A non-finite number (an infinite cost, a NaN slope) is printed as null, never as the
    Infinity/NaN that Python's json writes and other parsers reject."""
    import json

    import numpy as np

    from biped_opt import strict_json

    text = strict_json.dumps({"value": float("inf"), "d": [np.nan, np.float64(1.5)],
                              "a": np.array([-np.inf, 2.0]), "n": np.int64(3), "ok": np.True_})
    assert json.loads(text) == {"value": None, "d": [None, 1.5], "a": [None, 2.0], "n": 3,
                                "ok": True}
    # a failed optimisation: no grid point of the (absurd) bounds simulates
    main(["optimise", "--maneuver", "touchdown", "--theta0", "0.01", "--json",
          "--bounds", "u1=1e30,2e30"])
    out = json.loads(capsys.readouterr().out,
                     parse_constant=lambda name: pytest.fail(f"{name} in JSON output"))
    assert out["success"] is False and out["value"] is None


def test_a_closed_pipe_ends_the_command_quietly():
    """``sweep ... | head -c 10``: the reader leaves early; the command stops with status 0 and
    says nothing (no BrokenPipeError traceback), as a Unix filter does."""
    # ~1 MB of table: far more than a pipe holds, so the writer meets the closed pipe
    proc = subprocess.run(
        f"{sys.executable} -m biped_opt.cli.main sweep --maneuver touchdown --num 20001 "
        "--no-progress | head -c 10; exit ${PIPESTATUS[0]}",
        shell=True, executable="/bin/bash", capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and proc.stderr == "" and len(proc.stdout) == 10, proc


@pytest.mark.parametrize(("value", "fragment"), [
    ("abc", "ROS_DOMAIN_ID must be an integer in 0..232, got 'abc'"),
    ("300", "ROS_DOMAIN_ID must be an integer in 0..232, got 300"),
    ("-1", "ROS_DOMAIN_ID must be an integer in 0..232, got -1"),
])
@pytest.mark.parametrize("argv", [["launch"], ["replay", "{mcap}"]])
def test_a_bad_domain_in_the_environment_is_one_line(value, fragment, argv, places, monkeypatch,
                                                     capsys):
    monkeypatch.setenv("ROS_DOMAIN_ID", value)
    assert main([_fill(a, places) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and fragment in err, err


@pytest.mark.parametrize(("error", "fragment"), [
    (MemoryError(), "biped-opt sweep: error: not enough memory for this command"),
    (OSError(28, "No space left on device", "/x/s.json"),
     "biped-opt sweep: error: /x/s.json: No space left on device"),
    (KeyboardInterrupt(), "biped-opt sweep: interrupted"),
])
def test_what_the_machine_refuses_is_one_line(error, fragment, monkeypatch, capsys):
    """Out of memory, a full disk, Ctrl-C in the middle of the work: one line, no traceback
    (status 2, or 130 for an interrupted command as a shell gives it)."""
    from biped_opt.paper import sweeps

    def refuse(*_args, **_kwargs):
        raise error

    monkeypatch.setattr(sweeps, "sweep_fixed", refuse)  # (the command imports it as it runs)
    status = main(["sweep", "--maneuver", "touchdown", "--num", "3"])
    err = capsys.readouterr().err
    assert status == (130 if isinstance(error, KeyboardInterrupt) else 2)
    assert err == fragment + "\n", err


def test_resuming_a_study_whose_saved_spec_holds_a_5001_digit_seed_is_one_line(places, capsys,
                                                                              tmp_path):
    """The study file beside a table is read back on resume: an integer of more digits than
    Python converts there (a hand-edited or hostile file) is one line, not a traceback."""
    table = tmp_path / "t.csv"
    table.write_text("point\n")
    (tmp_path / "t.csv.study.json").write_text('{"seed": ' + "9" * 5001 + "}")
    status = main(["study", places["study"], "--out", str(table)])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert "t.csv.study.json is not valid JSON" in err


def test_the_recorder_node_refuses_parameters_it_cannot_record_even_without_autostart():
    out = subprocess.run([sys.executable, "-m", "biped_opt.nodes.recorder", "--ros-args", "-p",
                          "num:=0"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert out.stderr.strip() == ("recorder: error: cannot record from the parameters: num "
                                  "must be between 2 and 100000, got 0")


def test_large_lifts_the_size_limit(capsys):
    """--large compiles past the nodes' limits: the quadruped (20 coordinates) is described,
    not refused (a listing of it builds nothing beyond its description)."""
    assert main(["systems", "quadruped", "--large", "--json"]) == 0
    assert '"name": "quadruped"' in capsys.readouterr().out
