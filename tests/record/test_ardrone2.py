"""The AR.Drone 2.0 record through the resampling path, checked against the raw .mat arrays."""
import numpy as np
import pytest
from scipy.io import loadmat

from cdam_core.record.dataset import read_dataset, write_dataset
from cdam_core.record.realdata.ardrone2 import ARDRONE2_FILE, load_ardrone2


@pytest.fixture(scope="module")
def raw(bundled_record):
    """The raw arrays; the record ships in data/ardrone2, so missing is a failure."""
    mat = bundled_record(ARDRONE2_FILE)
    return loadmat(str(mat), squeeze_me=True, struct_as_record=False)["expData"].origData


@pytest.fixture(scope="module")
def ds(raw):
    return load_ardrone2()


def test_columns_span_and_grid(ds, raw):
    assert ds.inputs == ["motor1", "motor2", "motor3", "motor4"]
    assert ds.outputs == ["phi", "theta", "psi", "X", "Y", "Z"]
    assert ds.rate == 120.0
    np.testing.assert_allclose(np.diff(ds.t), 1 / 120.0, atol=1e-9)
    # the span both streams cover: navdata starts later, OptiTrack ends earlier
    assert ds.t[0] == pytest.approx(max(raw.otTime[0], raw.navTime[0]))
    assert ds.t[-1] <= min(raw.otTime[-1], raw.navTime[-1])
    assert ds.t[-1] > min(raw.otTime[-1], raw.navTime[-1]) - 1 / 120.0


def test_values_match_raw_streams(ds, raw):
    idx = np.searchsorted(raw.navTime, ds.t, side="right") - 1
    for k in range(4):   # motor PWM held between navdata packets
        np.testing.assert_array_equal(ds.column(f"motor{k + 1}"), raw.navMotor[k][idx])
    for k, name in enumerate(["X", "Y", "Z"]):
        np.testing.assert_allclose(ds.column(name), np.interp(ds.t, raw.otTime, raw.otPos[k]),
                                   atol=1e-12)
    for k, name in enumerate(["phi", "theta", "psi"]):
        np.testing.assert_allclose(ds.column(name),
                                   np.interp(ds.t, raw.otTime, np.unwrap(raw.otOrient[k])),
                                   atol=1e-12)


def test_other_rate_and_round_trip(tmp_path):
    d60 = load_ardrone2(rate=60.0)
    np.testing.assert_allclose(np.diff(d60.t), 1 / 60.0, atol=1e-9)
    p = tmp_path / "ardrone.csv"
    write_dataset(p, d60)
    back = read_dataset(p)
    assert back.inputs == d60.inputs and back.outputs == d60.outputs
    np.testing.assert_array_equal(back.data, d60.data)


def test_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match="rate"):
        load_ardrone2(rate=-1)
    with pytest.raises(FileNotFoundError):
        load_ardrone2(tmp_path / "none.mat")
    bad = tmp_path / "bad.mat"
    from scipy.io import savemat
    savemat(str(bad), {"other": np.zeros(3)})
    with pytest.raises(ValueError, match="not the expected AR.Drone record"):
        load_ardrone2(bad)
