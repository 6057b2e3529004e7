"""Check: bodyschema's LeRobot interchange read and written by LeRobot's own code (issue 35).

    MUJOCO_GL=egl .venv/bin/python bench/lerobot_check.py --lerobot-python /work/lerobot_venv/bin/python
        [--n 200] [--episodes 3] [--frames 30] [--work DIR]

Runs the bodyschema side with this interpreter (the project's venv) and the LeRobot side with --lerobot-python (a
second venv: lerobot 0.4.4 pins torch < 2.11, the project's torch is newer), through a script it writes into the work
folder. Checks, each printed with its figure:

1. export: `datagen` (nao_arm, babble) then `export dataset --to lerobot`; LeRobotDataset loads the folder and every
   frame's features (observation.state, action, images, ...) equal the store's arrays (max abs diff; images in 0-255).
2. normalisation: LeRobot's NormalizerProcessorStep with pi05's map (STATE, ACTION: QUANTILES; VISUAL: IDENTITY) built
   from the export's meta/stats.json normalises one DataLoader batch; the result equals 2 (x - q01) / (q99 - q01) - 1.
3. AV1: LeRobotDataset.create(use_videos=True) with 0.4.4's default codec (libsvtav1), a few episodes of smooth random
   RGB images + state + action, then `bodyschema import`; the imported images against the written ones (PSNR, max abs
   diff: AV1 is lossy) and against LeRobot's own decoding of the same files; state and action exact.

The LeRobot venv (~7 GB: torch 2.10's manylinux wheel loads the nvidia-*-cu12 libraries at import, CPU or not, and
no 2.10 CPU wheel is on the index; torchcodec needs a system FFmpeg, else the LeRobot side decodes with PyAV, LeRobot's
own fallback backend):

    python3.11 -m venv /work/lerobot_venv
    /work/lerobot_venv/bin/pip install torch==2.10.0 torchvision==0.25.0 torchcodec==0.10.0 lerobot==0.4.4
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

ROBOT = "nao_arm"

LEROBOT_SIDE = textwrap.dedent('''
    """The LeRobot side of bench/lerobot_check.py: `read ROOT STORE_NPZ OUT_JSON` or `write ROOT SPEC_JSON OUT_NPZ`."""
    import json
    import sys
    from pathlib import Path

    import av
    import cv2
    import numpy as np
    import torch

    import lerobot
    from lerobot.configs.types import FeatureType, NormalizationMode
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from lerobot.datasets.utils import dataset_to_policy_features
    from lerobot.processor import NormalizerProcessorStep, batch_to_transition, transition_to_batch


    def backend():
        """LeRobot's default decoder (torchcodec) where it loads (it needs a system FFmpeg), else its fallback, PyAV."""
        try:
            from torchcodec.decoders import VideoDecoder  # noqa: F401
            return None
        except Exception:
            return "pyav"


    def pi05_norm_map():
        try:
            from lerobot.policies.pi05.configuration_pi05 import PI05Config
            mapping, source = PI05Config.__dataclass_fields__["normalization_mapping"].default_factory(), "PI05Config"
        except Exception as e:  # the policy's extra deps missing: pi05's map, as written there
            mapping = {"VISUAL": NormalizationMode.IDENTITY, "STATE": NormalizationMode.QUANTILES,
                       "ACTION": NormalizationMode.QUANTILES}
            source = f"literal (PI05Config: {type(e).__name__})"
        return {FeatureType(k): NormalizationMode(v) for k, v in mapping.items()}, source


    def read(root, store_npz, out_json):
        ds = LeRobotDataset("local/bodyschema", root=root, video_backend=backend())
        ref = np.load(store_npz)
        worst = {key: 0.0 for key in ref.files}
        for i in range(len(ds)):
            item = ds[i]
            for key in ref.files:
                got = item[key].numpy().astype(np.float64)
                want = ref[key][i].astype(np.float64)
                if key in ds.meta.camera_keys:          # LeRobot: (C, H, W) float in [0, 1]; the store: uint8
                    want = (want[None] if want.ndim == 2 else want.transpose(2, 0, 1)) / 255.0
                    got, want = np.round(got * 255.0), np.round(want * 255.0)   # float32 / 255: 1e-5 off
                worst[key] = max(worst[key], float(np.abs(got - want.reshape(got.shape)).max()))
        norm_map, source = pi05_norm_map()
        features = dataset_to_policy_features(ds.meta.features)
        step = NormalizerProcessorStep(features=features, norm_map=norm_map, stats=ds.meta.stats)
        batch = next(iter(torch.utils.data.DataLoader(ds, batch_size=64, shuffle=False)))
        normed = transition_to_batch(step(batch_to_transition(dict(batch))))
        norm = {}
        for key, ft in features.items():
            if norm_map.get(ft.type) != NormalizationMode.QUANTILES:
                continue
            st = ds.meta.stats[key]
            q01, q99 = (torch.as_tensor(np.asarray(st[q]), dtype=torch.float32) for q in ("q01", "q99"))
            denom = torch.where(q99 == q01, torch.tensor(step.eps), q99 - q01)   # LeRobot's guard: a constant
            by_hand = 2.0 * (batch[key].float() - q01) / denom - 1.0
            out = normed[key]
            norm[key] = {"diff": float((out - by_hand).abs().max()), "finite": bool(torch.isfinite(out).all()),
                         "inside": float(((out >= -1) & (out <= 1)).float().mean()),
                         "range": [float(out.min()), float(out.max())], "constant": int((q99 == q01).sum()),
                         "size": int(q01.numel())}
        json.dump({"lerobot": lerobot.__version__, "torch": torch.__version__, "frames": len(ds),
                   "episodes": ds.meta.total_episodes, "backend": ds.video_backend, "worst": worst,
                   "norm_source": source, "norm": norm, "batch": int(batch["index"].shape[0])},
                  open(out_json, "w"))


    def smooth_random(rng, h, w):
        """An RGB frame of smooth colour blobs: random 7 x 10 colours, bicubic up to (h, w)."""
        coarse = rng.integers(0, 256, (7, 10, 3)).astype(np.float32)
        return np.clip(cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC), 0, 255).astype(np.uint8)


    def write(root, spec_json, out_npz):
        spec = json.load(open(spec_json))
        h, w, joints = spec["height"], spec["width"], spec["joints"]
        lo, hi = np.asarray(spec["q_low"], np.float32), np.asarray(spec["q_high"], np.float32)
        cam = "observation.images.front"
        features = {
            "observation.state": {"dtype": "float32", "shape": (len(joints),), "names": joints},
            "action": {"dtype": "float32", "shape": (len(joints),), "names": joints},
            cam: {"dtype": "video", "shape": (h, w, 3), "names": ["height", "width", "channels"]},
        }
        ds = LeRobotDataset.create("local/av1", fps=spec["fps"], features=features, root=root, robot_type="nao_arm",
                                   use_videos=True)
        rng = np.random.default_rng(spec["seed"])
        images, states, actions = [], [], []
        for _ in range(spec["episodes"]):
            for _ in range(spec["frames"]):
                q = (lo + (hi - lo) * rng.random(len(joints))).astype(np.float32)
                a = (lo + (hi - lo) * rng.random(len(joints))).astype(np.float32)
                image = smooth_random(rng, h, w)
                ds.add_frame({"observation.state": q, "action": a, cam: image, "task": "babble"})
                images.append(image)
                states.append(q)
                actions.append(a)
            ds.save_episode()
        ds.finalize()
        back = LeRobotDataset("local/av1", root=root, video_backend=backend())   # LeRobot decodes what it wrote
        decoded = [np.round(back[i][cam].numpy().transpose(1, 2, 0) * 255.0).astype(np.uint8)
                   for i in range(len(back))]
        video = sorted(Path(root, "videos").rglob("*.mp4"))
        with av.open(str(video[0])) as container:
            stream = container.streams.video[0]
            codec, pix_fmt = stream.codec_context.name, stream.codec_context.pix_fmt
        np.savez(out_npz, images=np.stack(images), states=np.stack(states), actions=np.stack(actions),
                 lerobot_decoded=np.stack(decoded), vcodec=np.str_(ds.vcodec), codec=np.str_(codec),
                 pix_fmt=np.str_(pix_fmt), files=np.int64(len(video)), backend=np.str_(back.video_backend))


    if __name__ == "__main__":
        {"read": read, "write": write}[sys.argv[1]](*sys.argv[2:])
''')


def bodyschema(args: list[str], cwd: Path) -> None:
    """One CLI command as a user types it; stops the check on failure."""
    done = subprocess.run([sys.executable, "-m", "bodyschema.cli", *args], cwd=cwd, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"`bodyschema {' '.join(args)}` exit {done.returncode}:\n{done.stderr.strip()[-1500:]}")


def lerobot_side(python: str, args: list[str], work: Path) -> float:
    """The LeRobot script in the other venv (offline: the datasets are local); wall seconds."""
    script = work / "lerobot_side.py"
    script.write_text(LEROBOT_SIDE)
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_DATASETS_OFFLINE": "1", "HF_LEROBOT_HOME": str(work / "hf")}
    start = time.monotonic()
    done = subprocess.run([python, str(script), *args], cwd=work, capture_output=True, text=True, env=env)
    if done.returncode != 0:
        raise SystemExit(f"LeRobot side `{args[0]}` exit {done.returncode}:\n{done.stderr.strip()[-3000:]}")
    return time.monotonic() - start


def report(name: str, ok: bool, figure: str) -> bool:
    print(f"[{'PASS' if ok else 'FAIL'}] {name}: {figure}", flush=True)
    return ok


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10.0 * np.log10(255.0**2 / mse)


def check_export(python: str, work: Path, n: int) -> list[bool]:
    import zarr

    bodyschema(["datagen", "--robot", ROBOT, "--n", str(n), "--sampler", "babble", "--out", "store.zarr",
                "--no-progress"], work)
    bodyschema(["export", "dataset", "store.zarr", "exported", "--to", "lerobot"], work)
    ours = json.loads((work / "exported" / "meta" / "bodyschema.json").read_text())
    store = zarr.open_group(str(work / "store.zarr"), mode="r")
    np.savez(work / "store.npz", **{feature: np.asarray(store[array]) for feature, array in ours["arrays"].items()})
    seconds = lerobot_side(python, ["read", str(work / "exported"), str(work / "store.npz"), str(work / "read.json")],
                           work)
    got = json.loads((work / "read.json").read_text())
    print(f"LeRobot {got['lerobot']} (torch {got['torch']}) loaded {got['frames']} frames, {got['episodes']} "
          f"episode(s), in {seconds:.0f} s")
    results = [report("export: frames", got["frames"] == n, f"{got['frames']} of {n}")]
    for feature, diff in got["worst"].items():
        unit = " (0-255)" if feature.startswith("observation.images.") else ""
        results.append(report(f"export: {feature} = store.{ours['arrays'][feature]}", diff == 0.0,
                              f"max abs diff {diff:g}{unit} over every frame"))
    results.append(report("normalise: QUANTILES keys", bool(got["norm"]), f"{sorted(got['norm'])} (norm map: "
                          f"{got['norm_source']}; batch of {got['batch']})"))
    for feature, fig in got["norm"].items():
        ok = fig["finite"] and fig["diff"] < 1e-5
        results.append(report(f"normalise: {feature}", ok, f"max |step - 2(x-q01)/(q99-q01)-1| {fig['diff']:.2g}, "
                              f"range [{fig['range'][0]:+.3f}, {fig['range'][1]:+.3f}], "
                              f"{100 * fig['inside']:.1f}% inside [-1, 1]"
                              + (f"; {fig['constant']} of {fig['size']} constant (q01 = q99: LeRobot's eps, -> -1)"
                                 if fig["constant"] else "")))
    return results


def check_av1(python: str, work: Path, episodes: int, frames: int) -> list[bool]:
    import zarr

    ours = json.loads((work / "exported" / "meta" / "bodyschema.json").read_text())["body"]
    spec = {"height": 56, "width": 80, "fps": 20, "seed": 0, "episodes": episodes, "frames": frames,
            "joints": ours["joint_names"], "q_low": ours["q_low"], "q_high": ours["q_high"]}
    (work / "spec.json").write_text(json.dumps(spec))
    seconds = lerobot_side(python, ["write", str(work / "av1"), str(work / "spec.json"), str(work / "written.npz")],
                           work)
    written = np.load(work / "written.npz")
    print(f"LeRobot wrote {episodes} x {frames} frames ({written['files']} video file(s), vcodec "
          f"{written['vcodec']}, {written['pix_fmt']}, PyAV decoder {written['codec']}, LeRobot's backend "
          f"{written['backend']}) in {seconds:.0f} s")
    bodyschema(["import", "av1", "--robot", ROBOT, "--angles", "rad", "--out", "imported.zarr"], work)
    store = zarr.open_group(str(work / "imported.zarr"), mode="r")
    image, q = np.asarray(store["image"]), np.asarray(store["q"])
    sent, theirs = written["images"], written["lerobot_decoded"]
    av1 = str(written["vcodec"]) == "libsvtav1" and "av1" in str(written["codec"])   # dav1d / libdav1d / av1
    results = [report("av1: codec", av1, f"written {written['vcodec']}, decoded by {written['codec']}"),
               report("av1: frames", image.shape == sent.shape, f"imported {image.shape}, written {sent.shape}")]
    if image.shape != sent.shape:
        return results
    diff = np.abs(image.astype(np.int16) - sent.astype(np.int16))   # lossy: a figure; > 20 dB: not noise
    results.append(report("av1: imported vs written", psnr(image, sent) > 20.0,
                          f"PSNR {psnr(image, sent):.1f} dB (worst frame {min(map(psnr, image, sent)):.1f}), mean "
                          f"abs diff {diff.mean():.2f}, max abs diff {diff.max()} (0-255; crf 30, yuv420p)"))
    nearest = [int(np.argmax([psnr(got, want) for want in sent])) for got in image]   # no frame shifted or swapped
    shifted = int(np.sum(np.asarray(nearest) != np.arange(len(sent))))
    results.append(report("av1: frame order", shifted == 0, f"{shifted} of {len(sent)} imported frames nearer "
                          "another written frame than their own"))
    both = np.abs(image.astype(np.int16) - theirs.astype(np.int16))
    results.append(report("av1: imported vs LeRobot's decoding", both.max() <= 1,
                          f"max abs diff {both.max()}, PSNR {psnr(image, theirs):.1f} dB"))
    results.append(report("av1: state", np.array_equal(q, written["states"]),
                          f"max abs diff {np.abs(q - written['states']).max():g}"))
    if "target" in store:
        target = np.asarray(store["target"])
        results.append(report("av1: action -> target", np.array_equal(target, written["actions"]),
                              f"max abs diff {np.abs(target - written['actions']).max():g}"))
    else:
        results.append(report("av1: action -> target", False, "no target array in the imported store"))
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lerobot-python", required=True, help="python of a venv with lerobot 0.4.4")
    parser.add_argument("--n", type=int, default=200, help="frames of the exported store")
    parser.add_argument("--episodes", type=int, default=3, help="AV1 dataset: episodes")
    parser.add_argument("--frames", type=int, default=30, help="AV1 dataset: frames per episode")
    parser.add_argument("--work", type=Path, default=None, help="work folder (kept); default a temporary one")
    args = parser.parse_args()
    os.environ.setdefault("MUJOCO_GL", "egl")
    with tempfile.TemporaryDirectory(prefix="lerobot_check_") as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        results = check_export(args.lerobot_python, work, args.n)
        results += check_av1(args.lerobot_python, work, args.episodes, args.frames)
    print(f"{sum(results)} of {len(results)} checks pass")
    sys.exit(0 if all(results) else 1)


if __name__ == "__main__":
    main()
