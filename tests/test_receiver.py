"""The receivers (dsm/maps/receiver.py) do not depend on the map's resolution."""
import pytest


@pytest.mark.slow
def test_receivers_do_not_depend_on_the_map_resolution():
    """A directional light's receivers are the same set at R = 1 to 7 as at R = 8 and 64 (at
    R < 8 one receiver on the fitted border fell outside: 620 against 621)."""
    import dsm
    from conftest import base_config
    res = dsm.run(base_config(scene=[{"builtin": "plane_box"}], camera={"resolution": [48, 48]},
                              map={"resolution": [1, 2, 3, 5, 7, 8, 64]}, scheme=[{"name": "none"}]), report=False)
    counts = {r["resolution"]: (r["n_receivers"], r["n_excluded_outside"]) for r in res.rows}
    assert len(set(counts.values())) == 1, counts
    assert counts[8][1] == 0
