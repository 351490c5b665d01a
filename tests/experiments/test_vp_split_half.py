"""The split-half protocol of the Victoria Park map figures
(`experiments.paper.victoria_park.split_half`): each half's setting from its own F1 only,
judged on the other half."""

import math

from experiments.paper.victoria_park.split_half import EXTRACTORS, derive_per_half, split_half_rows


def _record(extractor, k, f1_a, f1_b, precision_a=0.9, precision_b=0.8):
    r = {"extractor": extractor, "confirm_scans": k, "landmarks": 100 + k}
    r |= {"precision": 0.85, "recall": 0.9, "f1": 0.87}
    r |= {"precision_1_1000": precision_a, "recall_1_1000": 0.9 + k / 100, "f1_1_1000": f1_a}
    r |= {"precision_1001_2000": precision_b, "recall_1001_2000": 0.8 + k / 100}
    r |= {"f1_1001_2000": f1_b, "landmarks_1_1000": 60 + k, "landmarks_1001_2000": 40 + k}
    return r


def _records():
    # the published detections' F1: highest at 3 on the first half, at 5 on the second
    f1 = {2: (0.80, 0.70), 3: (0.90, 0.72), 4: (0.85, 0.74), 5: (0.84, 0.80), 6: (0.83, 0.75)}
    rows = [_record("detections", k, a, b) for k, (a, b) in f1.items()]
    # an extractor whose own F1 would pick other settings: it must not matter
    rows += [_record("geometric", k, 1.0 - a, 1.0 - b) for k, (a, b) in f1.items()]
    return rows


def test_each_half_derives_from_its_own_f1_only():
    assert derive_per_half(_records()) == {"1_1000": 3, "1001_2000": 5}
    # the other half's figures do not move it
    rows = _records()
    for r in rows:
        r["f1_1001_2000"] = 0.5 if r["confirm_scans"] != 2 else 0.99
    assert derive_per_half(rows)["1_1000"] == 3


def test_a_half_whose_best_setting_is_at_an_end_derives_nothing():
    rows = _records()
    for r in rows:
        r["f1_1001_2000"] = 1.0 - r["confirm_scans"] / 10  # highest at 2, the first candidate
    assert derive_per_half(rows) == {"1_1000": 3, "1001_2000": None}
    out = split_half_rows(rows, derive_per_half(rows), preset_confirm=4)
    (row,) = [
        r for r in out if r["extractor"] == "detections" and r["derived_on"] == "scans 1001-2000"
    ]
    assert math.isnan(row["confirm_scans"]) and math.isnan(row["precision"])


def test_every_extractor_is_judged_on_the_half_its_setting_never_saw():
    rows = _records()
    out = split_half_rows(rows, {"1_1000": 3, "1001_2000": 5}, preset_confirm=4)
    geo = {r["derived_on"]: r for r in out if r["extractor"] == "geometric"}
    a, b, whole = geo["scans 1-1000"], geo["scans 1001-2000"], geo["scans 1-2000"]
    assert a["judged_on"] == "scans 1001-2000" and a["confirm_scans"] == 3
    assert a["recall"] == 0.8 + 3 / 100 and a["landmarks"] == 43  # k = 3's second half
    assert b["judged_on"] == "scans 1-1000" and b["confirm_scans"] == 5
    assert b["recall"] == 0.9 + 5 / 100 and b["landmarks"] == 65  # k = 5's first half
    assert whole["judged_on"] == "scans 1-2000 (in-sample)" and whole["confirm_scans"] == 4
    assert whole["precision"] == 0.85 and whole["landmarks"] == 104
    # extractors without records (bailey, paper here) get rows of NaN figures, not errors
    assert {r["extractor"] for r in out} == set(EXTRACTORS)
    assert all(math.isnan(r["precision"]) for r in out if r["extractor"] == "bailey")


def test_the_table_is_written_with_a_row_per_extractor_and_protocol(tmp_path):
    from experiments.paper.victoria_park.split_half import TABLE

    rows = split_half_rows(_records(), {"1_1000": 3, "1001_2000": 5}, preset_confirm=4)
    md, csv_path = TABLE.write(tmp_path, rows)
    assert csv_path.read_text().count("\n") == 1 + 3 * len(EXTRACTORS)
    assert "scans 1-2000 (in-sample)" in md.read_text()
