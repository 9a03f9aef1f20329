"""Thresholds on your own scene, as a test file you copy: run with `pytest examples/`.

dsm's pytest plugin gives the fixture `dsm_results` (no import needed): it runs a config once per
test session, so each test below reads the same run. Each helper of `dsm.testing` fails on a filter
that matches nothing (a threshold never passes on no case) and lists the offending cases, with the
path of their error image, when it fails.
"""
from pathlib import Path

from dsm.testing import assert_no_worse_than, assert_oracle_gap, assert_rate

CONFIG = {
    "experiment": {"name": "my_scene"},
    "camera": {"resolution": [96, 72]},
    "scene": [{"file": str(Path(__file__).with_name("my_scene.xml"))}],
    "map": {"resolution": [256, 512]},
    "scheme": [{"name": "constant", "bias": "2 texel"}, {"name": "receiver_plane"}, {"name": "adaptive"}],
    "timing": {"repeats": 1},
}


def test_receiver_plane_keeps_acne_below_half_a_percent(dsm_results):
    assert_rate(dsm_results(CONFIG), "acne_rate", below=0.005, scheme="receiver_plane")


def test_adaptive_errs_no_more_than_a_two_texel_constant_bias(dsm_results):
    assert_no_worse_than(dsm_results(CONFIG), "error_rate", "adaptive", than="constant", tolerance=0.002)


def test_adaptive_is_within_0_2_percent_of_the_best_single_bias(dsm_results):
    assert_oracle_gap(dsm_results(CONFIG), below=0.002, oracle="world", scheme="adaptive")
