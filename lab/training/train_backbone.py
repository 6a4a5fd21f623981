"""Train the backbone on synthetic patches and export ``engine/weights/backbone.npz``.

    python -m lab.training.train_backbone --out engine/weights/backbone.npz --steps N --seed 0
        [--resume CKPT] [--device cpu|cuda] [--run-dir out/backbone] ...

Data: a pool of ``pool_chunks`` chunks of ``chunk`` patches from :mod:`patch_data`. Chunk k is
drawn from ``numpy.random.default_rng([seed, 1, k])`` in a worker process; every
``steps_per_chunk`` steps the next chunk replaces the oldest one, so the pool at any step is a
deterministic function of (seed, step) and a resumed run regenerates exactly the pool it had.
Each batch draws pool entries with ``default_rng([seed, 3, step])`` and applies a fresh uniform
random rotation (the patches' geometric features are rotation invariant and cached).

Loss: L1 on UDF / r, weighted 1.5 / (0.5 + u) (3x at the surface, 1x at u = 1).
Adam, linear warm-up then cosine decay, gradient-norm clip 1. Validation: a fixed held-out set
drawn from ``default_rng(val_seed)`` (default 20,000 patches), compared with the nearest-point
distance. Logs to ``run_dir/train.log`` and stdout; checkpoints ``run_dir/last.pt`` (and
exports ``--out``) every ``checkpoint_minutes``.
"""

import argparse
import json
import math
import multiprocessing as mp
import sys
import time
from pathlib import Path
from typing import Dict

import numpy as np

from engine import backbone as bb
from . import patch_data as pd


def make_chunk(args_tuple):
    """Chunk ``k`` of the training stream with its cached geometric features (worker side)."""
    seed, k, size, config = args_tuple
    data = pd.generate_patches(size, np.random.default_rng([seed, 1, k]))
    data["geo"] = bb.geometric_features_np(data["rel"], data["mask"], config)
    return {key: data[key] for key in ("rel", "mask", "udf", "geo")}


def validation_set(size: int, seed: int, config: Dict) -> Dict[str, np.ndarray]:
    data = pd.generate_patches(size, np.random.default_rng(seed))
    data["geo"] = bb.geometric_features_np(data["rel"], data["mask"], config)
    data["baseline"] = pd.nearest_point_baseline(data["rel"], data["mask"])
    return data


def evaluate(predict, val: Dict[str, np.ndarray]) -> Dict[str, float]:
    """Mean absolute error of ``predict(val) -> (B,)`` vs the nearest-point baseline (patch units).

    Returns mae / baseline for: all, sparse (<= 16 real points), near (true UDF < 0.25),
    noisy, clean, and each family.
    """
    pred = predict(val)
    err = np.abs(pred - val["udf"])
    base = np.abs(val["baseline"] - val["udf"])
    real = val["mask"].sum(axis=1)
    groups = {"all": np.ones(len(err), bool), "sparse": real <= 16, "near": val["udf"] < 0.25,
              "noisy": val["noise"] > 0, "clean": val["noise"] == 0}
    for i, family in enumerate(pd.FAMILIES):
        groups[family] = val["family"] == i
    out = {}
    for name, sel in groups.items():
        if sel.any():
            out[name] = float(err[sel].mean())
            out[name + "_baseline"] = float(base[sel].mean())
            out[name + "_count"] = int(sel.sum())
    return out


def random_rotations_torch(gen: np.random.Generator, n: int):
    import torch
    return torch.from_numpy(pd._random_rotations(gen, n).astype(np.float32))


class Logger:
    def __init__(self, path: Path):
        self.file = open(path, "a", buffering=1)

    def __call__(self, message: str):
        line = time.strftime("%H:%M:%S ") + message
        print(line, flush=True)
        self.file.write(line + "\n")


def learning_rate(step: int, steps: int, peak: float, warmup: int) -> float:
    if step < warmup:
        return peak * (step + 1) / warmup
    progress = (step - warmup) / max(1, steps - warmup)
    return peak * (0.01 + 0.99 * 0.5 * (1 + math.cos(math.pi * min(1.0, progress))))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default=str(bb.DEFAULT_WEIGHTS), help="weights file to export")
    parser.add_argument("--steps", type=int, default=6000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--resume", default=None, help="checkpoint (.pt) to continue from")
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    parser.add_argument("--run-dir", default="out/backbone")
    parser.add_argument("--batch", type=int, default=512)
    parser.add_argument("--lr", type=float, default=2e-3)
    parser.add_argument("--warmup", type=int, default=200)
    parser.add_argument("--chunk", type=int, default=1024, help="patches per generated chunk")
    parser.add_argument("--pool-chunks", type=int, default=64, help="chunks held in the pool")
    parser.add_argument("--steps-per-chunk", type=int, default=3)
    parser.add_argument("--workers", type=int, default=1, help="data generator processes")
    parser.add_argument("--threads", type=int, default=1, help="torch threads")
    parser.add_argument("--val-size", type=int, default=20000)
    parser.add_argument("--val-seed", type=int, default=990001)
    parser.add_argument("--val-every", type=int, default=500)
    parser.add_argument("--checkpoint-minutes", type=float, default=2.0)
    parser.add_argument("--hidden", type=int, default=bb.DEFAULT_CONFIG["hidden"],
                        help="per-point feature width H")
    parser.add_argument("--head-width", type=int, default=bb.DEFAULT_CONFIG["head_width"],
                        help="width of the head MLP and of the attention-query MLP")
    args = parser.parse_args(argv)

    import torch
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    run_dir = Path(args.run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    log = Logger(run_dir / "train.log")
    log("command: python -m lab.training.train_backbone " + " ".join(sys.argv[1:] if argv is None else argv))

    device = torch.device(args.device)
    model = bb.build_backbone_torch(dict(bb.DEFAULT_CONFIG, hidden=args.hidden,
                                         head_width=args.head_width)).to(device)
    config = model.config
    optimizer = torch.optim.Adam(model.parameters(), lr=args.lr)
    step, elapsed = 0, 0.0
    if args.resume:
        state = torch.load(args.resume, map_location=device)
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        step, elapsed = state["step"], state["elapsed"]
        log(f"resumed from {args.resume} at step {step} ({elapsed / 60:.1f} min trained)")
    params = sum(p.numel() for p in model.parameters())
    log(f"backbone: {params} parameters, {bb.macs_per_query(config)} MAC/query at 64 points")

    t0 = time.time()
    val = validation_set(args.val_size, args.val_seed, config)
    log(f"validation set: {len(val['udf'])} patches (seed {args.val_seed}) in {time.time() - t0:.0f} s")

    ctx = mp.get_context("fork")
    workers = ctx.Pool(args.workers)
    pool_chunks = args.pool_chunks
    # At step s the pool holds chunks [first, first + pool_chunks) with first = s // spc.
    first = step // args.steps_per_chunk
    t0 = time.time()
    chunks = workers.map(make_chunk, [(args.seed, k, args.chunk, config)
                                      for k in range(first, first + pool_chunks)])
    # Chunk k lives in slot k % pool_chunks, whatever step the run starts at.
    chunks = sorted(zip(range(first, first + pool_chunks), chunks), key=lambda kc: kc[0] % pool_chunks)
    pool = {key: np.concatenate([c[key] for _, c in chunks]) for key in chunks[0][1]}
    log(f"pool: {pool_chunks} chunks x {args.chunk} patches in {time.time() - t0:.0f} s")
    slot_size = args.chunk
    pending = {}

    def request(k):
        if k not in pending:
            pending[k] = workers.apply_async(make_chunk, ((args.seed, k, args.chunk, config),))

    def to_torch(batch):
        return {key: torch.from_numpy(value).to(device) for key, value in batch.items()}

    def predict_val(data):
        model.eval()
        out = []
        with torch.no_grad():
            for s in range(0, len(data["udf"]), 4096):
                part = to_torch({k: data[k][s:s + 4096] for k in ("rel", "mask", "geo")})
                out.append(model(part["rel"], part["mask"], part["geo"]).cpu().numpy())
        model.train()
        return np.concatenate(out)

    def save(final=False):
        state = {"model": model.state_dict(), "optimizer": optimizer.state_dict(), "step": step,
                 "elapsed": elapsed, "args": vars(args)}
        torch.save(state, run_dir / "last.tmp")
        (run_dir / "last.tmp").replace(run_dir / "last.pt")
        meta = {"step": step, "steps": args.steps, "seed": args.seed, "final": final,
                "train_minutes": round(elapsed / 60, 1), "args": vars(args)}
        bb.save_backbone(model.cpu(), args.out, meta)
        model.to(device)

    model.train()
    running, running_n = 0.0, 0
    last_ckpt = time.time()
    last_log, last_log_step = time.time(), step
    tic = time.time()
    while step < args.steps:
        # Stream: chunk (first + pool_chunks) replaces chunk first at each chunk boundary.
        if step % args.steps_per_chunk == 0 and step // args.steps_per_chunk > first:
            incoming = first + pool_chunks
            request(incoming)
            chunk = pending.pop(incoming).get()
            slot = (incoming % pool_chunks) * slot_size
            for key in pool:
                pool[key][slot:slot + slot_size] = chunk[key]
            first += 1
        request(first + pool_chunks)
        request(first + pool_chunks + 1)

        gen = np.random.default_rng([args.seed, 3, step])
        index = gen.integers(0, len(pool["udf"]), args.batch)
        rot = random_rotations_torch(gen, args.batch)
        batch = to_torch({k: pool[k][index] for k in ("rel", "mask", "udf", "geo")})
        rel = torch.einsum("bij,bnj->bni", rot.to(device), batch["rel"])
        lr = learning_rate(step, args.steps, args.lr, args.warmup)
        for group in optimizer.param_groups:
            group["lr"] = lr
        pred = model(rel, batch["mask"], batch["geo"])
        weight = 1.5 / (0.5 + batch["udf"])
        loss = (weight * (pred - batch["udf"]).abs()).mean()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        optimizer.step()
        running += loss.item()
        running_n += 1
        step += 1
        now = time.time()
        elapsed += now - tic
        tic = now

        if step % 100 == 0:
            rate = (step - last_log_step) * args.batch / (now - last_log)
            log(f"step {step}/{args.steps} loss {running / running_n:.4f} lr {lr:.2e} "
                f"{rate:.0f} samples/s {elapsed / 60:.1f} min")
            running, running_n, last_log, last_log_step = 0.0, 0, now, step
        if step % args.val_every == 0 or step == args.steps:
            m = evaluate(predict_val, val)
            log(f"val step {step}: mae {m['all']:.4f} (nearest point {m['all_baseline']:.4f}) "
                f"sparse {m['sparse']:.4f} ({m['sparse_baseline']:.4f}) "
                f"near {m['near']:.4f} ({m['near_baseline']:.4f})")
            tic = time.time()
        if time.time() - last_ckpt > 60 * args.checkpoint_minutes or step == args.steps:
            save(final=step == args.steps)
            last_ckpt = time.time()
            tic = time.time()

    workers.terminate()
    m = evaluate(predict_val, val)
    m["step"], m["train_minutes"] = step, round(elapsed / 60, 1)
    (run_dir / "final_metrics.json").write_text(json.dumps(m, indent=1))
    log("final: " + json.dumps(m))


if __name__ == "__main__":
    main()
