import dataclasses
import gzip
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import avrisk
from avrisk.learning.ngsim.files import (
    I80_LATERAL,
    I80_PAIRS,
    NGSIM_DIR_ENV,
    US101_FILE,
    ngsim_dir,
    ngsim_file,
)
from avrisk.learning.ngsim.loaders import (
    lateral_pair_split,
    load_i80_lateral,
    load_i80_pairs,
    load_us101,
    read_i80_pairs_table,
)
from avrisk.learning.ngsim.packed import DECIMALS_KEY, EXCEPTIONS_SUFFIX
from avrisk.learning.ngsim.samples import FT, CarFollowingPairs, episode_bounds
from tests.ngsim_originals import original_file

I80_HEADER = (
    "pair_id,period,follower_id,leader_id,lane_id,split,in_manifest,source_file,t,"
    "x_follower,v_follower,a_follower,x_leader,v_leader,a_leader,leader_length,"
    "spacing,dv"
)


def write_gz(path, lines):
    with gzip.open(path, "wt") as f:
        f.write("\n".join(lines) + "\n")


def test_i80_pairs_are_converted_from_feet_to_metres_and_sorted(tmp_path):
    # Rows deliberately out of order; pair 7 has no lane in the source.
    write_gz(
        tmp_path / "pairs.csv.gz",
        [
            I80_HEADER,
            "7,0500pm-0515pm,11,12,,test,0,b.csv,5.1,200,30,-1,260,28,0,15,45,2",
            "3,0400pm-0415pm,1,2,4,train,1,a.csv,0.1,110,10.5,0.5,170,10,0,16,44,0.5",
            "3,0400pm-0415pm,1,2,4,train,1,a.csv,0.0,100,10,1,160,10,0,16,44,0",
            "7,0500pm-0515pm,11,12,,test,0,b.csv,5.0,197,30,-2,257,28,0,15,45,2",
        ],
    )
    p = load_i80_pairs(tmp_path / "pairs.csv.gz")
    assert isinstance(p, CarFollowingPairs) and len(p) == 4
    assert p.pair_id.tolist() == [3, 3, 7, 7]
    assert p.t.tolist() == [0.0, 0.1, 5.0, 5.1]
    assert p.x_follower[0] == pytest.approx(100 * FT) == pytest.approx(30.48)
    assert p.v_follower[0] == pytest.approx(10 * 0.3048)
    assert p.a_follower[0] == pytest.approx(0.3048)
    assert p.leader_length[0] == pytest.approx(16 * 0.3048)
    assert p.gap[0] == pytest.approx(44 * 0.3048)
    assert p.dv[2] == pytest.approx(2 * 0.3048)
    assert p.lane.tolist() == [4, 4, -1, -1]
    assert p.split.tolist() == ["train", "train", "test", "test"]
    assert p.in_manifest.tolist() == [True, True, False, False]
    assert p.period[2] == "0500pm-0515pm"


def assert_same_arrays(a, b):
    """Every column equal in dtype and bits (so -0.0 differs from 0.0)."""
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        assert x.dtype == y.dtype, f.name
        if x.dtype == np.float64:
            x, y = x.view(np.int64), y.view(np.int64)
        np.testing.assert_array_equal(x, y, err_msg=f.name)


def test_packed_pairs_decode_decimals_and_exceptions_and_recompute_spacing(
    tmp_path,
):
    write_gz(
        tmp_path / "pairs.csv.gz",
        [
            I80_HEADER,
            "3,0400pm-0415pm,1,2,,train,1,a.csv,0.0,100.25,10,1,160,10,0,16,43.75,0",
            "3,0400pm-0415pm,1,2,,train,1,a.csv,0.1,-0.0,10,1,160,10,0,16,144.0,0",
            "3,0400pm-0415pm,1,2,,train,1,a.csv,0.2,4.4e-16,10,1,160,10,0,16,144.0,0",
        ],
    )
    original = load_i80_pairs(tmp_path / "pairs.csv.gz")
    table = read_i80_pairs_table(tmp_path / "pairs.csv.gz")
    table = table.drop_columns(["source_file", "spacing", "dv", "x_follower"])
    # x_follower as hundredths of a foot; -0.0 and 4.4e-16 are not such decimals
    decimals = pa.field("x_follower", pa.int64(), metadata={DECIMALS_KEY: b"2"})
    table = table.append_column(decimals, pa.array([10025, None, None]))
    table = table.append_column(
        "x_follower" + EXCEPTIONS_SUFFIX, pa.array([None, -0.0, 4.4e-16])
    )
    pq.write_table(table, tmp_path / "pairs.parquet")
    packed = load_i80_pairs(tmp_path / "pairs.parquet")
    assert_same_arrays(packed, original)
    assert np.signbit(packed.x_follower[1]) and packed.lane.tolist() == [-1] * 3


def test_the_lateral_pairs_keep_si_units_and_name_the_follower_columns(tmp_path):
    d = pa.dictionary(pa.int16(), pa.string())
    table = pa.table(
        {
            "pair_id": ["5-4", "5-4"],
            "time": [0.1, 0.0],
            "duration": [30.0, 30.0],
            "vehicle_id": pa.array(["5", "5"]).cast(d),
            "frame_id": [11.0, 10.0],
            "local_x": [5.2, 5.1],
            "local_y": [101.0, 100.0],
            "v_length": [4.5, 4.5],
            "v_width": [1.8, 1.8],
            "v_class": pa.array(["2", "2"]).cast(d),
            "v_vel": [10.1, 10.0],
            "v_acc": [0.5, 0.4],
            "lane_id": pa.array(["2", "2"]).cast(d),
            "preceding": pa.array(["4", "4"]).cast(d),
            "space_headway": [20.0, 20.5],
            "time_headway": [2.0, 2.05],
            "preceding_local_y": [121.0, 120.5],
            "preceding_length": [5.0, 5.0],
            "preceding_width": [2.0, 2.0],
            "preceding_class": pa.array(["3", "3"]).cast(d),
            "preceding_vel": [9.0, 9.1],
            "preceding_acc": [0.0, 0.1],
        }
    )
    pq.write_table(table, tmp_path / "lat.parquet")
    lat = load_i80_lateral(tmp_path / "lat.parquet")
    assert lat.t.tolist() == [0.0, 0.1]
    assert lat.frame.tolist() == [10, 11]
    assert lat.follower_id.tolist() == [5, 5] and lat.leader_id.tolist() == [4, 4]
    assert lat.lateral.tolist() == [5.1, 5.2] and lat.x.tolist() == [100.0, 101.0]
    assert lat.lane.tolist() == [2, 2] and lat.leader_class.tolist() == [3, 3]
    assert lat.gap.tolist() == pytest.approx([15.5, 15.0])


def test_us101_marks_missing_leaders_as_nan_and_converts_milliseconds(tmp_path):
    header = (
        "Vehicle_ID,Frame_ID,Total_Frames,Global_Time,local_x(m),local_y(m),v_Vel(m),"
        "v_Acc(m),H_v_Vel(m),H_v_Acc(m),Space_Headway(m),Time_Headway"
    )
    write_gz(
        tmp_path / "us.csv.gz",
        [
            header,
            "9,101,2,1118847866500,5.5,12.0,10.0,0.0,0.1,,0.0,9999.99",
            "9,100,2,1118847866400,5.4,11.0,10.0,0.0,,,24.9,2.4",
        ],
    )
    us = load_us101(tmp_path / "us.csv.gz")
    assert us.frame.tolist() == [100, 101]
    assert us.t[1] - us.t[0] == pytest.approx(0.1)
    assert us.space_headway[0] == 24.9 and np.isnan(us.space_headway[1])
    assert us.time_headway[0] == 2.4 and np.isnan(us.time_headway[1])
    assert us.lane.tolist() == [2, 2]  # 12 ft lanes: 5.4 m is in lane 2


def test_episode_bounds_split_runs_of_equal_keys():
    starts, ends = episode_bounds(np.array(["a", "a", "b", "c", "c"]))
    assert starts.tolist() == [0, 2, 3] and ends.tolist() == [2, 3, 5]
    assert [len(x) for x in episode_bounds([])] == [0, 0]


def test_a_lateral_pair_whose_follower_is_an_i80_test_follower_is_held_out(
    lateral_stub,
):
    pairs = CarFollowingPairs(
        pair_id=np.array([1, 2]),
        period=np.array(["0400pm-0415pm", "0400pm-0415pm"]),
        follower_id=np.array([10, 20]),
        leader_id=np.array([11, 21]),
        lane=np.array([2, 3]),
        split=np.array(["test", "train"]),
        in_manifest=np.array([True, True]),
        **{
            k: np.zeros(2)
            for k in ("t", "x_follower", "v_follower", "a_follower", "x_leader",
                      "v_leader", "a_leader", "leader_length", "gap", "dv")
        },
    )  # fmt: skip
    lat = lateral_stub([10, 20])
    split = lateral_pair_split(lat, pairs, test_fraction=0.0)
    assert split.tolist() == ["test", "train"]
    split = lateral_pair_split(lat, pairs, test_fraction=1.0)
    assert split.tolist() == ["test", "train"]  # a train follower never leaks


def test_by_default_the_packed_i80_files_shipped_in_the_package_are_read(
    monkeypatch,
):
    monkeypatch.delenv(NGSIM_DIR_ENV, raising=False)
    shipped = Path(avrisk.__file__).parent / "data" / "ngsim"
    assert ngsim_dir() == shipped and (shipped / "SOURCE.md").is_file()
    assert ngsim_file(I80_PAIRS) == shipped / I80_PAIRS.packed
    assert ngsim_file(I80_LATERAL) == shipped / I80_LATERAL.packed
    with pytest.raises(FileNotFoundError, match=f"{shipped} lacks {US101_FILE}"):
        load_us101()  # not shipped


def test_the_shipped_ngsim_files_load_with_plausible_si_values(monkeypatch):
    monkeypatch.delenv(NGSIM_DIR_ENV, raising=False)
    pairs = load_i80_pairs()
    assert len(pairs) == 147_521
    assert set(np.unique(pairs.split)) == {"train", "test"}
    assert 2.0 < np.median(pairs.v_follower) < 20.0  # m/s, congested I-80
    assert np.all(pairs.gap > 0) and np.median(pairs.leader_length) < 6.0
    lat = load_i80_lateral()
    assert len(lat) == 68_339 and np.unique(lat.pair_id).size == 142
    assert set(np.unique(lat.lane)) <= {1, 2, 3, 4, 5, 6}


@pytest.mark.parametrize(
    ("files", "load"), [(I80_PAIRS, load_i80_pairs), (I80_LATERAL, load_i80_lateral)]
)
def test_the_shipped_files_give_the_arrays_of_the_originals_bit_for_bit(
    files, load, monkeypatch
):
    monkeypatch.delenv(NGSIM_DIR_ENV, raising=False)
    assert_same_arrays(load(), load(original_file(files.original)))


def test_the_original_us101_file_loads_with_plausible_si_values():
    us = load_us101(original_file(US101_FILE))
    assert len(us) == 214_267 and np.unique(us.vehicle_id).size == 370
    assert 0.0 < np.nanmedian(us.speed) < 30.0  # m/s
