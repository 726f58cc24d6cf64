"""A bounded, seeded run of the readers' mutation fuzzer (tools/fuzz.py).

Every reader and loader gets a few hundred mutated files; each case runs in a
child process so that a crash or a hang is reported with its input instead of
killing the test run. ``make fuzz`` runs the long campaign.
"""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

TOOL = Path(__file__).resolve().parents[1] / "tools" / "fuzz.py"
CASES = 300  # per reader: 19 readers, ~2 ms a case, in two child processes


@pytest.fixture(scope="module")
def fuzz():
    if not TOOL.exists():
        pytest.skip(f"{TOOL} is absent")
    spec = importlib.util.spec_from_file_location("occgp_tools_fuzz", TOOL)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_cases_are_a_function_of_seed_reader_and_index(fuzz):
    for name in ("pcd_binary", "graph", "xyz_gz", "scan_folder"):
        reader = fuzz.readers()[name]
        assert reader.case(0, 57) == reader.case(0, 57)
        assert reader.case(0, 57) != reader.case(1, 57)


def test_mutations_change_header_fields(fuzz):
    seed = fuzz.readers()["pcd_ascii"].seeds()[0]
    rng = np.random.default_rng(0)
    edited = {fuzz._edit_text_field(rng, seed, fuzz._header_end(seed, "pcd")) for _ in range(50)}
    assert len(edited) > 20
    assert all(e[fuzz._header_end(e, "pcd"):] == seed[fuzz._header_end(seed, "pcd"):]
               for e in edited if b"DATA ascii\n" in e)


def test_ros_map_and_stamps_mutations_reach_their_targets(fuzz):
    ros = fuzz.readers()["ros_map"]
    seeds = {fuzz._split_pair(d) for d in ros.seeds()}
    cases = [tuple(ros.case(0, i).values()) for i in range(len(seeds), len(seeds) + 200)]
    yaml_seeds, pgm_seeds = {y for y, _ in seeds}, {p for _, p in seeds}
    assert sum(y not in yaml_seeds for y, _ in cases) > 50      # YAML files mutated
    assert sum(p not in pgm_seeds for _, p in cases) > 50       # PGM images mutated
    assert any(b"*a" in y for y, _ in cases)                    # aliases tried
    from occgp.octree._stamps import STAMPS_MAGIC

    stamps = fuzz.readers()["stamps_ot"]
    assert all(STAMPS_MAGIC in seed for seed in stamps.seeds()[:3])
    heads = {seed[:seed.find(STAMPS_MAGIC)] for seed in stamps.seeds()}
    cases = [stamps.case(0, i)["case.ot"] for i in range(10, 210)]
    in_block = [c for c in cases if c[:c.find(STAMPS_MAGIC)] in heads]
    assert len(in_block) > 80      # most cases keep the OctoMap data, edit the block


def test_hostile_ros_maps_are_rejected(fuzz, tmp_path):
    keys = (b"resolution: 0.1\norigin: [0.0, 0.0, 0.0]\nnegate: 0\noccupied_thresh: 0.65\n"
            b"free_thresh: 0.196\n")
    laughs = b'a: &a [1, 1]\nb: &b [*a, *a]\nimage: case.pgm\n' + keys
    for yaml_text in (laughs, b"image: /dev/zero\n" + keys, b"image: /dev/stdin\n" + keys,
                      b"image: .\n" + keys, b"mode: " + b"9" * 5000 + b"\nimage: case.pgm\n"
                      + keys):
        files = {"case.yaml": yaml_text, "case.pgm": b"P5 " + b"9" * 5000 + b" 1 255\n"}
        assert fuzz.run_case("ros_map", files, tmp_path)["outcome"] == "rejected", yaml_text
    files = {"case.yaml": b"image: case.pgm\n" + keys, "case.pgm": b"P5 " + b"9" * 5000}
    assert fuzz.run_case("ros_map", files, tmp_path) == {"outcome": "rejected",
                                                         "type": "ValueError"}


def test_outcomes_are_classified(fuzz, tmp_path):
    ok = fuzz.run_case("xyz", {"case.xyz": b"1 2 3\n4 5 6\n"}, tmp_path)
    assert ok == {"outcome": "ok"}
    rejected = fuzz.run_case("xyz", {"case.xyz": b"1 2\n"}, tmp_path)
    assert rejected == {"outcome": "rejected", "type": "ValueError"}
    rejected = fuzz.run_case("from_bytes", {"case.bytes": b"junk"}, tmp_path)
    assert rejected["outcome"] == "rejected"


@pytest.mark.slow
def test_seeds_are_read_and_used(fuzz, tmp_path):
    for name in fuzz._NAMES:
        reader = fuzz.readers()[name]
        n_seeds = 1 if name == "scan_folder" else len(reader.seeds())
        for index in range(n_seeds):
            assert fuzz.run_case(name, reader.case(0, index), tmp_path) == {"outcome": "ok"}, \
                (name, index)


@pytest.mark.slow
def test_bounded_fuzz_run(fuzz, tmp_path):
    rows, findings = fuzz.run_campaign(fuzz._NAMES, CASES, seed=0, jobs=2, timeout=10.0,
                                       save_dir=tmp_path)
    assert [r[1] for r in rows] == [CASES] * len(fuzz._NAMES)
    report = "\n".join(fuzz.format_finding(f) for f in findings)
    assert not findings, (f"{len(findings)} crash / hang / unclear exception(s):\n{report}\n"
                          + fuzz.format_table(rows))
