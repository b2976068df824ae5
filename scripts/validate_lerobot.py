#!/usr/bin/env python3
"""Check a LeRobot v3.0 dataset the way LeRobot's loader reads it, with pyarrow and PyAV only.

    validate_lerobot.py DATASET [--json]

Checks meta/info.json (fields, features), that every data parquet's schema matches the
non-video features (a shape [1] feature is a plain column, [n] a list of n), the tasks and
episodes tables (episode index ranges contiguous, lengths, file locations), one parquet row per
frame with timestamps on the 1/fps grid (timestamp == frame_index / fps), and for every video
feature one decoded frame per row at from_timestamp + timestamp (within the loader's 1e-4 s
tolerance), of the size the feature declares. Depth-map videos are dequantised with the
parameters in their feature's info, and the median depth under the mask is reported per frame.

Prints a verdict (JSON with --json) and exits 0 when the dataset passes, 1 when it does not,
2 when it cannot be read at all.
"""

import argparse
import json
import math
import sys
from pathlib import Path

import av
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

TOLERANCE_S = 1e-4  # LeRobotDataset's default tolerance_s
DEFAULT_FEATURES = {
    "timestamp": "float32",
    "frame_index": "int64",
    "episode_index": "int64",
    "index": "int64",
    "task_index": "int64",
}
INFO_FIELDS = {
    "codebase_version": str,
    "fps": int,
    "features": dict,
    "total_episodes": int,
    "total_frames": int,
    "total_tasks": int,
    "chunks_size": int,
    "data_path": str,
}
ARROW_TYPES = {
    "float32": pa.float32(),
    "float64": pa.float64(),
    "int64": pa.int64(),
    "int32": pa.int32(),
    "bool": pa.bool_(),
    "string": pa.string(),
}


class Report:
    def __init__(self):
        self.errors = []
        self.facts = {}

    def err(self, msg):
        self.errors.append(msg)

    def check(self, cond, msg):
        if not cond:
            self.err(msg)
        return cond


def check_info(root, r):
    info = json.loads((root / "meta/info.json").read_text())
    for key, typ in INFO_FIELDS.items():
        r.check(isinstance(info.get(key), typ), f"info.json: {key} missing or not {typ.__name__}")
    r.check(info.get("codebase_version") == "v3.0", f"codebase_version {info.get('codebase_version')!r} is not v3.0")
    r.check(isinstance(info.get("fps"), int) and info["fps"] > 0, "fps must be a positive integer")
    feats = info.get("features", {})
    for name, ft in feats.items():
        r.check("/" not in name, f"feature {name!r} has a '/'")
        for k in ("dtype", "shape", "names"):
            r.check(k in ft, f"feature {name}: no {k}")
        shape = ft.get("shape")
        r.check(isinstance(shape, list) and shape and all(isinstance(s, int) and s > 0 for s in shape),
                f"feature {name}: shape {shape!r} is not a list of positive ints")
        if ft.get("dtype") in ("video", "image"):
            r.check(len(shape) == 3, f"feature {name}: an image shape has 3 dims (h, w, c)")
            r.check(ft.get("names") == ["height", "width", "channels"], f"feature {name}: names must be height, width, channels")
    for name, dtype in DEFAULT_FEATURES.items():
        ft = feats.get(name)
        if r.check(ft is not None, f"default feature {name} missing"):
            r.check(ft["dtype"] == dtype and ft["shape"] == [1], f"default feature {name} must be {dtype} [1]")
    videos = [k for k, f in feats.items() if f.get("dtype") == "video"]
    if videos:
        r.check(isinstance(info.get("video_path"), str), "info.json: video features but no video_path")
    return info, videos


def expected_type(ft):
    base = ARROW_TYPES.get(ft["dtype"])
    if base is None:
        return None
    if ft["shape"] == [1]:
        return base
    if len(ft["shape"]) == 1:
        return pa.list_(base, ft["shape"][0])
    return None


def check_data(root, info, videos, r):
    feats = info["features"]
    columns = {k: f for k, f in feats.items() if f["dtype"] not in ("video",)}
    paths = sorted((root / "data").glob("*/*.parquet"))
    if not r.check(paths, "no data/*/*.parquet"):
        return None
    tables = []
    for p in paths:
        schema = pq.read_schema(p)
        names = set(schema.names) - {"__index_level_0__"}
        r.check(names == set(columns),
                f"{p.relative_to(root)}: columns {sorted(names ^ set(columns))} differ from the features")
        for name, ft in columns.items():
            if name not in schema.names:
                continue
            want, got = expected_type(ft), schema.field(name).type
            if want is None:
                r.err(f"feature {name}: dtype {ft['dtype']} shape {ft['shape']} not checked")
            elif pa.types.is_list(got) and pa.types.is_fixed_size_list(want):
                r.check(got.value_type == want.value_type, f"{name}: {got} is not {want}")
            else:
                r.check(got == want, f"{name}: parquet type {got} is not {want}")
        tables.append(pq.read_table(p))
    data = pa.concat_tables(tables)
    r.facts["rows"] = data.num_rows
    r.check(data.num_rows == info["total_frames"], f"{data.num_rows} rows, total_frames {info['total_frames']}")
    idx = data.column("index").to_numpy()
    r.check(np.array_equal(idx, np.arange(len(idx))), "index is not 0..total_frames-1 in order")
    return data


def check_tasks(root, info, data, r):
    t = pq.read_table(root / "meta/tasks.parquet")
    pandas_meta = t.schema.pandas_metadata or {}
    r.check(pandas_meta.get("index_columns") == ["task"], "tasks.parquet: the task text is not the (pandas) index 'task'")
    r.check({"task", "task_index"} <= set(t.column_names), "tasks.parquet: needs task and task_index")
    r.check(t.num_rows == info["total_tasks"], f"{t.num_rows} tasks, total_tasks {info['total_tasks']}")
    ti = t.column("task_index").to_pylist()
    r.check(ti == list(range(len(ti))), "task_index is not 0..n-1")
    if data is not None:
        used = set(data.column("task_index").to_pylist())
        r.check(used <= set(ti), f"frames use task indices {sorted(used - set(ti))} not in tasks.parquet")
    r.facts["tasks"] = t.column("task").to_pylist()


def check_episodes(root, info, videos, data, r):
    paths = sorted((root / "meta/episodes").glob("*/*.parquet"))
    if not r.check(paths, "no meta/episodes/*/*.parquet"):
        return []
    ep = pa.concat_tables([pq.read_table(p) for p in paths]).to_pylist()
    need = {"episode_index", "tasks", "length", "data/chunk_index", "data/file_index",
            "dataset_from_index", "dataset_to_index", "meta/episodes/chunk_index", "meta/episodes/file_index"}
    for v in videos:
        need |= {f"videos/{v}/{k}" for k in ("chunk_index", "file_index", "from_timestamp", "to_timestamp")}
    missing = need - set(ep[0].keys()) if ep else need
    if not r.check(not missing, f"episodes table lacks {sorted(missing)}"):
        return []
    r.check(len(ep) == info["total_episodes"], f"{len(ep)} episodes, total_episodes {info['total_episodes']}")
    fps = info["fps"]
    expect_from = 0
    for i, e in enumerate(ep):
        name = f"episode {e['episode_index']}"
        r.check(e["episode_index"] == i, f"{name}: episode_index out of order (row {i})")
        r.check(e["dataset_from_index"] == expect_from, f"{name}: dataset_from_index {e['dataset_from_index']}, expected {expect_from}")
        r.check(e["dataset_to_index"] - e["dataset_from_index"] == e["length"], f"{name}: to - from != length")
        r.check(e["length"] > 0, f"{name}: empty")
        expect_from = e["dataset_to_index"]
        path = root / info["data_path"].format(chunk_index=e["data/chunk_index"], file_index=e["data/file_index"])
        r.check(path.exists(), f"{name}: {path.relative_to(root)} missing")
        if data is not None:
            a, b = e["dataset_from_index"], e["dataset_to_index"]
            rows = data.slice(a, b - a)
            r.check(set(rows.column("episode_index").to_pylist()) == {i}, f"{name}: rows {a}..{b} are not all episode {i}")
            fi = rows.column("frame_index").to_numpy()
            r.check(np.array_equal(fi, np.arange(b - a)), f"{name}: frame_index is not 0..length-1")
            ts = rows.column("timestamp").to_numpy().astype(np.float64)
            off = np.abs(ts - fi / fps)
            r.check(off.max(initial=0) <= TOLERANCE_S, f"{name}: timestamps off the 1/fps grid by up to {off.max():.2e} s")
        for v in videos:
            span = e[f"videos/{v}/to_timestamp"] - e[f"videos/{v}/from_timestamp"]
            r.check(abs(span - e["length"] / fps) <= TOLERANCE_S, f"{name}: {v} spans {span} s for {e['length']} frames")
    r.check(data is None or expect_from == data.num_rows, "episodes do not cover every row")
    return ep


def dequantise(codes, vi):
    lo, hi, shift = vi.get("video.depth_min", 0.01), vi.get("video.depth_max", 10.0), vi.get("video.shift", 3.5)
    if vi.get("video.use_log", True):
        a, b = math.log(lo + shift), math.log(hi + shift)
        d = np.exp(a + codes.astype(np.float64) * (b - a) / 4095.0) - shift
    else:
        d = lo + codes.astype(np.float64) * (hi - lo) / 4095.0
    return np.clip(d, lo, hi)


def decode(path, ft):
    """Every frame of a video: (time in s, array). Depth maps as 12-bit codes, others as decoded."""
    vi = ft.get("info", {})
    is_depth = vi.get("is_depth_map") or vi.get("video.is_depth_map")
    out = []
    with av.open(str(path)) as c:
        s = c.streams.video[0]
        for f in c.decode(s):
            if is_depth:
                arr = f.to_ndarray(format="gray12le")
            elif ft["shape"][2] == 1:
                arr = f.to_ndarray(format="gray")
            else:
                arr = f.to_ndarray(format="rgb24")
            out.append((float(f.time), arr))
    return out


def check_videos(root, info, videos, ep, data, r):
    feats, fps = info["features"], info["fps"]
    decoded = {}
    r.facts["video_frames"] = {}
    for v in videos:
        ft = feats[v]
        h, w, c = ft["shape"]
        vi = ft.get("info", {})
        files = sorted({(e[f"videos/{v}/chunk_index"], e[f"videos/{v}/file_index"]) for e in ep})
        n = 0
        for chunk, file in files:
            path = root / info["video_path"].format(video_key=v, chunk_index=chunk, file_index=file)
            if not r.check(path.exists(), f"{v}: {path.relative_to(root)} missing"):
                continue
            frames = decode(path, ft)
            decoded[(v, chunk, file)] = frames
            n += len(frames)
            for i, (t, arr) in enumerate(frames):
                if abs(t - i / fps) > TOLERANCE_S:
                    r.err(f"{v}: frame {i} at {t} s, not {i / fps} s")
                    break
            if frames:
                r.check(frames[0][1].shape[:2] == (h, w), f"{v}: frames are {frames[0][1].shape[:2]}, feature says {(h, w)}")
            with av.open(str(path)) as cont:
                st = cont.streams.video[0]
                if "video.pix_fmt" in vi:
                    r.check(st.pix_fmt == vi["video.pix_fmt"], f"{v}: pix_fmt {st.pix_fmt}, info says {vi['video.pix_fmt']}")
                if "video.codec" in vi:
                    r.check(st.codec.canonical_name == vi["video.codec"], f"{v}: codec {st.codec.canonical_name}, info says {vi['video.codec']}")
        r.facts["video_frames"][v] = n
        r.check(n == info["total_frames"], f"{v}: {n} video frames for {info['total_frames']} rows")
        # The loader's lookup: every row's frame at from_timestamp + timestamp, within tolerance.
        if data is None:
            continue
        for e in ep:
            frames = decoded.get((v, e[f"videos/{v}/chunk_index"], e[f"videos/{v}/file_index"]), [])
            times = np.array([t for t, _ in frames])
            a, b = e["dataset_from_index"], e["dataset_to_index"]
            ts = data.slice(a, b - a).column("timestamp").to_numpy().astype(np.float64)
            for q in e[f"videos/{v}/from_timestamp"] + ts:
                if times.size == 0 or np.abs(times - q).min() > TOLERANCE_S:
                    r.err(f"{v}: episode {e['episode_index']}: no frame at {q:.6f} s (within {TOLERANCE_S} s)")
                    break
    return decoded


def depth_under_mask(info, videos, decoded, r):
    feats = info["features"]
    depth = [v for v in videos if feats[v].get("info", {}).get("is_depth_map")]
    mask = [v for v in videos if v.endswith("mask") and v not in depth]
    if not depth or not mask:
        return
    dk, mk = depth[0], mask[0]
    vi = feats[dk]["info"]
    medians = []
    for (v, chunk, file), frames in sorted(decoded.items()):
        if v != dk:
            continue
        masks = decoded.get((mk, chunk, file), [])
        for (_, codes), (_, m) in zip(frames, masks):
            sel = m.reshape(codes.shape) > 127
            medians.append(float(np.median(dequantise(codes[sel], vi))) if sel.any() else None)
    r.facts["masked_depth_median_m"] = medians


def check_stats(root, info, r):
    p = root / "meta/stats.json"
    if not p.exists():
        return
    stats = json.loads(p.read_text())
    for k, s in stats.items():
        r.check(k in info["features"], f"stats.json: {k} is not a feature")
        for q in ("min", "max", "mean", "std", "count"):
            r.check(q in s, f"stats.json: {k} has no {q}")


def load_with_lerobot(root, info, r):
    """Load the dataset with LeRobot itself and read every frame (lerobot >= 0.6, Python >= 3.12)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset  # noqa: PLC0415

    ds = LeRobotDataset("hitl/export", root=root)
    r.check(len(ds) == info["total_frames"], f"LeRobotDataset: {len(ds)} frames, total_frames {info['total_frames']}")
    r.check(ds.num_episodes == info["total_episodes"], f"LeRobotDataset: {ds.num_episodes} episodes")
    shapes = {}
    for i in range(len(ds)):
        item = ds[i]
        for k, v in item.items():
            if hasattr(v, "shape"):
                shapes.setdefault(k, tuple(v.shape))
        r.check(int(item["index"]) == i, f"LeRobotDataset: item {i} has index {int(item['index'])}")
    r.facts["lerobot_frames"] = len(ds)
    r.facts["lerobot_shapes"] = {k: list(v) for k, v in shapes.items()}
    for key in ("observation.images.color", "observation.images.depth", "observation.images.mask"):
        if key in info["features"]:
            r.check(key in shapes, f"LeRobotDataset: items have no {key}")
    # LeRobot's own dequantised depth agrees with this script's (its unit: depth_output_unit).
    medians = r.facts.get("masked_depth_median_m") or []
    dk, mk = "observation.images.depth", "observation.images.mask"
    if medians and medians[0] is not None and dk in shapes and mk in shapes:
        item = ds[0]
        per_m = 1000.0 if getattr(ds, "depth_output_unit", "mm") == "mm" else 1.0
        sel = item[mk][0] > 0.5
        got = float(item[dk][0][sel].median()) / per_m
        r.facts["lerobot_masked_depth_median_m"] = got
        r.check(abs(got - medians[0]) <= 0.002, f"LeRobotDataset: depth under the mask {got} m, the video says {medians[0]} m")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--json", action="store_true", help="print the verdict as one JSON object")
    ap.add_argument("--lerobot", action="store_true", help="also load it with LeRobotDataset and read every frame")
    a = ap.parse_args()
    r = Report()
    root = a.dataset
    try:
        info, videos = check_info(root, r)
    except (OSError, ValueError) as e:
        print(f"validate_lerobot: cannot read {root / 'meta/info.json'}: {e}", file=sys.stderr)
        return 2
    data = check_data(root, info, videos, r)
    check_tasks(root, info, data, r)
    ep = check_episodes(root, info, videos, data, r)
    decoded = check_videos(root, info, videos, ep, data, r) if ep else {}
    depth_under_mask(info, videos, decoded, r)
    check_stats(root, info, r)
    if a.lerobot:
        load_with_lerobot(root, info, r)
    verdict = {"ok": not r.errors, "errors": r.errors, "episodes": len(ep), "frames": info["total_frames"],
               "fps": info["fps"], "videos": videos, **r.facts}
    if data is not None:
        # Per-frame columns the caller may compare with the recording.
        for k in ("capture_time_ns", "observation.target_pose_gt"):
            if k in data.column_names:
                verdict[k] = data.column(k).to_pylist()
    if a.json:
        print(json.dumps(verdict))
    else:
        print("ok" if verdict["ok"] else "FAILED", f"{verdict['episodes']} episodes, {verdict['frames']} frames")
        for e in r.errors:
            print("  " + e)
    return 0 if verdict["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
