"""Train the radius selector against the frozen backbone and export ``engine/weights/selector.npz``.

    python -m lab.training.train_selector --out engine/weights/selector.npz --seed 0
        [--shapes 40] [--dense-shapes 10] [--queries 3000] [--epochs 10] [--head-epochs 5]
        [--cache-dir out/selector_cache]

1. Error curves: for ``--shapes`` car and garment *training* shapes each (benchmark train seeds,
   disjoint from the test seeds), and ``--dense-shapes`` more each scanned with
   ``--dense-points`` points, ``--queries`` band queries per shape, the backbone's absolute
   UDF error at ``--candidates`` radii from rho_min R to rho_max R, evenly spaced in r or in
   log r (``--spacing``; the defaults: K = 7, 0.012 ... 0.024), cached per shape, resumable.
2. Targets: each query's curve averaged over its ``--expected-over`` nearest queries of the same
   shape (the expected error there), the parabola vertex through that curve's minimum
   (:mod:`.radius_targets`) kept ``--target-inset`` of the span off the range's ends, loss
   weight w = max(e) - min(e); loss w * |r_hat - r*| / (r_max - r_min), plus a hinge on the
   output logit 2 beyond the targets' largest (zero in use; it pulls outputs back out of the
   sigmoid's flat ends). The first ``--head-epochs`` train the head only, from the standardised
   extra features (code at 0, encoder frozen); then everything trains.
3. Evaluation on held-out queries of held-out shapes, rooms included although rooms are never
   trained on: the 5 training seeds per domain after ``--shapes`` (1 clean, 2 sparse, 2 noisy)
   and :data:`BALANCED_SEEDS` (15 per domain, 5 of each condition, past every training and
   dense seed): mean absolute UDF error of every single fixed candidate radius (and the
   product's default fixed radius), the curvature policy at the product's default range, the
   learned selector and the per-query oracle, run through the backbone at each policy's radii;
   per domain and per scan condition (:func:`evaluate`; ``python -m
   lab.training.evaluate_selector`` evaluates a selector file alone).
"""

import argparse
import hashlib
import json
import time
from pathlib import Path

import numpy as np

from engine.backbone import DEFAULT_WEIGHTS
from engine.curvature import curvature_radii
from engine.field import backbone_predictor
from engine.selector import NumpySelector, build_selector_torch, predict_radii
from engine.weights_file import save_weights
from ..bench.dataset import train_seeds
from engine.settings import ReconstructSettings
from .radius_targets import (candidate_radii, expected_errors, inset_targets, loss_weights,
                             parabola_targets)
from .selector_data import (DENSE_POINTS, TRAINING_CONDITIONS, backbone_udf, condition_of,
                            dense_conditions, shape_cache, shape_scene)

TRAIN_DOMAINS = ("cars", "garments")
EVAL_DOMAINS = ("cars", "garments", "rooms")
LOGIT_MARGIN = 2.0  # the penalty starts this far (in logits) beyond the targets
HELD_OUT = 5
BALANCED_SEEDS = tuple(range(100, 115))
"""The balanced held-out shapes of every domain: training seeds 100-114, scanned clean, sparse
and noisy five times each (the seed's condition, :func:`.selector_data.condition_of`), never
trained on while ``--shapes`` + 5 + ``--dense-shapes`` stays at most 100."""


def training_shapes(args):
    """(domain, seed, scan condition or None for the seed's own, TRAINING_CONDITIONS index) of
    every training shape: ``--shapes`` per domain, then ``--dense-shapes`` per domain scanned
    densely, clean and noisy in turn (seeds past the held-out ones; counted as clean or noisy
    in the progress lines)."""
    for domain in TRAIN_DOMAINS:
        for seed in train_seeds(domain, args.shapes):
            yield domain, seed, None, condition_of(seed)
    dense = dense_conditions(args.dense_points)
    first = args.shapes + HELD_OUT
    for domain in TRAIN_DOMAINS:
        for i, seed in enumerate(train_seeds(domain, first + args.dense_shapes)[first:]):
            name = ("clean", "noisy")[i % 2]
            yield domain, seed, dense[name], TRAINING_CONDITIONS.index(name)


def grid_radii(args) -> np.ndarray:
    """The K candidate radii the error curves are measured at."""
    return candidate_radii(args.rho_min * args.parent_radius, args.rho_max * args.parent_radius,
                           args.candidates, args.spacing)


def load_training_set(args, predict):
    parts = []
    shapes = list(training_shapes(args))
    for i, (domain, seed, condition, label) in enumerate(shapes):
        started = time.time()
        part = shape_cache(domain, seed, predict, args.queries, args.parent_radius,
                           grid_radii(args), Path(args.cache_dir), condition=condition)
        # per shape: the nearest queries must lie on the same surface
        part["expected"] = expected_errors(part["errors"], part["queries"], args.expected_over)
        part["condition"] = np.full(len(part["errors"]), label)
        parts.append(part)
        print(f"shape {i + 1}/{len(shapes)}: {domain} {seed} "
              f"{condition.name if condition else TRAINING_CONDITIONS[label]} "
              f"({time.time() - started:.1f} s)", flush=True)
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def train(args, data):
    import torch

    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    r_min, r_max = args.rho_min * args.parent_radius, args.rho_max * args.parent_radius
    targets = inset_targets(parabola_targets(data["expected"], grid_radii(args)), r_min, r_max,
                            args.target_inset)
    share = np.clip((targets - r_min) / (r_max - r_min), 1e-3, 1 - 1e-3)
    z_max = float(np.abs(np.log(share / (1 - share))).max()) + LOGIT_MARGIN
    targets = torch.from_numpy(targets.astype(np.float32))
    weights = torch.from_numpy(loss_weights(data["expected"]).astype(np.float32))
    weights = weights / weights.mean()  # scale-free: keeps the learning rate meaningful
    rel, mask, extra = (torch.from_numpy(data[k]) for k in ("rel", "mask", "extra"))
    condition = torch.from_numpy(data["condition"])
    model = build_selector_torch()
    model.standardise_extra(extra)
    optimiser = torch.optim.Adam(model.parameters(), lr=args.lr)
    steps_per_epoch = len(targets) // args.batch
    # no warm-up: its peak learning rate is where outputs overshoot into the sigmoid's flat end
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimiser,
                                                          args.epochs * steps_per_epoch)
    generator = torch.Generator().manual_seed(args.seed)
    # The head learns first, from the extra features alone (the code starts at zero, the encoder
    # frozen): trained together from the start, the 256 code columns drown the 9 features and
    # the selector answers one radius for every query (SELECTOR_CARD.md).
    encoder = [p for name, p in model.named_parameters() if not name.startswith(("mlp", "out"))]
    if args.head_epochs:
        with torch.no_grad():
            model.code.weight.zero_()
            model.code.bias.zero_()
    for epoch in range(args.epochs):
        for p in encoder:
            p.requires_grad_(epoch >= args.head_epochs)
        order = torch.randperm(len(targets), generator=generator)
        total = 0.0
        radius_sum = torch.zeros(len(TRAINING_CONDITIONS), dtype=torch.float64)
        radius_count = torch.zeros(len(TRAINING_CONDITIONS), dtype=torch.float64)
        for step in range(steps_per_epoch):
            batch = order[step * args.batch:(step + 1) * args.batch]
            z = model.logit(rel[batch], mask[batch], extra[batch])
            r_hat = r_min + (r_max - r_min) * torch.sigmoid(z)
            loss = torch.mean(weights[batch] * torch.abs(r_hat - targets[batch])) / (r_max - r_min)
            # zero unless an output is well past every target, in the sigmoid's flat ends (where
            # the L1 term's gradient vanishes); pulls such outputs back
            loss = loss + torch.mean(torch.relu(z.abs() - z_max))
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            schedule.step()
            total += loss.item()
            radius_sum.index_add_(0, condition[batch], r_hat.detach().double())
            radius_count.index_add_(0, condition[batch], torch.ones(len(batch), dtype=torch.float64))
        means = " ".join(f"{name} {mean:.4f}" for name, mean in
                         zip(TRAINING_CONDITIONS, (radius_sum / radius_count.clamp(min=1)).tolist()))
        print(f"epoch {epoch + 1}/{args.epochs} loss {total / steps_per_epoch:.5f} "
              f"mean r_hat: {means}", flush=True)
    return model


def held_out_seeds(args) -> list:
    """The 5 training seeds after the ``--shapes`` trained on."""
    return list(range(args.shapes, args.shapes + HELD_OUT))


def evaluate(args, predict, selector, seeds):
    """Mean |UDF error| per policy, per domain and per scan condition, on the held-out training
    shapes ``seeds`` of every domain (unit frame)."""
    product = ReconstructSettings()
    fixed_radii = sorted(set(np.round(grid_radii(args), 6)) | {product.radius})
    results = {}
    for domain in EVAL_DOMAINS:
        errors = {f"fixed {r:.4f}": [] for r in fixed_radii}
        errors.update({"curvature": [], "learned": [], "oracle grid radius": []})
        conditions = []
        for seed in seeds:
            scene = shape_scene(domain, seed, args.queries, query_seed=1)
            tree, points, queries, udf = (scene[k] for k in ("tree", "points", "queries", "udf"))
            conditions += [scene["condition"]] * len(queries)
            per_radius = []
            for r in fixed_radii:
                err = np.abs(backbone_udf(predict, tree, points, queries, r) - udf)
                errors[f"fixed {r:.4f}"].append(err)
                per_radius.append(err)
            errors["oracle grid radius"].append(np.min(per_radius, axis=0))
            radii = curvature_radii(tree, points, queries, product.parent_radius,
                                    product.rho_min, product.rho_max)
            errors["curvature"].append(np.abs(backbone_udf(predict, tree, points, queries,
                                                           radii) - udf))
            radii = predict_radii(selector, tree, points, queries, args.parent_radius,
                                  args.rho_min, args.rho_max)
            errors["learned"].append(np.abs(backbone_udf(predict, tree, points, queries,
                                                         radii) - udf))
            errors.setdefault("learned radius", []).append(radii)
        conditions = np.array(conditions)
        joined = {k: np.concatenate(v) for k, v in errors.items()}
        results[domain] = summary(joined)
        for name in TRAINING_CONDITIONS:
            if (conditions == name).any():
                results[domain][name] = summary({k: v[conditions == name]
                                                 for k, v in joined.items()})
        print(domain, json.dumps(results[domain]), flush=True)
    return results


def summary(errors) -> dict:
    """Means of each policy's errors (and of the learned radii), with the best fixed radius."""
    means = {k: float(np.mean(v)) for k, v in errors.items()}
    fixed = {k: v for k, v in means.items() if k.startswith("fixed")}
    best = min(fixed, key=fixed.get)
    means["best fixed"] = fixed[best]
    means["best fixed radius"] = float(best.split()[1])
    return means


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="engine/weights/selector.npz")
    parser.add_argument("--cache-dir", default="out/selector_cache")
    parser.add_argument("--shapes", type=int, default=40, help="training shapes per domain")
    parser.add_argument("--dense-shapes", type=int, default=10,
                        help="more training shapes per domain, scanned densely (clean, noisy)")
    parser.add_argument("--dense-points", type=int, default=DENSE_POINTS,
                        help="points in a dense training scan")
    parser.add_argument("--queries", type=int, default=3000, help="queries per shape")
    parser.add_argument("--epochs", type=int, default=10)
    parser.add_argument("--batch", type=int, default=512)
    parser.add_argument("--lr", type=float, default=3e-3)
    parser.add_argument("--head-epochs", type=int, default=5,
                        help="first epochs that train only the head (encoder frozen, code at 0)")
    parser.add_argument("--expected-over", type=int, default=64,
                        help="nearest queries whose error curves are averaged into a target's "
                             "(1: the paper's per-query curves)")
    parser.add_argument("--target-inset", type=float, default=0.001,
                        help="share of the radius span that targets keep off its ends (most "
                             "targets sit at the top end: 0.005 left them 0.00006 short of it, "
                             "which cost more than the clean queries won)")
    parser.add_argument("--parent-radius", type=float, default=0.024)
    parser.add_argument("--rho-min", type=float, default=0.5)
    parser.add_argument("--rho-max", type=float, default=1.0)
    parser.add_argument("--candidates", type=int, default=7,
                        help="K: radii the error curves are measured at, from rho_min R to "
                             "rho_max R")
    parser.add_argument("--spacing", choices=("linear", "log"), default="linear",
                        help="candidate radii evenly spaced in r or in log r (a range spanning "
                             "a factor of several)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args(argv)
    if args.shapes + HELD_OUT + args.dense_shapes > BALANCED_SEEDS[0]:
        parser.error(f"--shapes + {HELD_OUT} + --dense-shapes must stay at most "
                     f"{BALANCED_SEEDS[0]}: the balanced held-out shapes start there")
    started = time.time()
    predict = backbone_predictor("cpu")
    # error curves belong to one backbone: key the cache by its weights
    digest = hashlib.sha256(DEFAULT_WEIGHTS.read_bytes()).hexdigest()[:12]
    args.cache_dir = str(Path(args.cache_dir) / f"backbone_{digest}")
    data = load_training_set(args, predict)
    cached = time.time()
    print(f"{len(data['udf'])} training queries cached in {cached - started:.0f} s", flush=True)
    model = train(args, data)
    trained = time.time()
    selector = NumpySelector({k: v.detach().numpy() for k, v in model.state_dict().items()},
                             model.config)
    metrics = evaluate(args, predict, selector, held_out_seeds(args))
    balanced = evaluate(args, predict, selector, BALANCED_SEEDS)
    meta = {"args": vars(args), "training_queries": int(len(data["udf"])),
            "seconds": {"cache": cached - started, "train": trained - cached,
                        "evaluate": time.time() - trained},
            "held_out_mean_abs_udf_error": metrics,
            "balanced_held_out_mean_abs_udf_error": balanced}
    save_weights(model, args.out, meta)
    Path(args.out).with_suffix(".json").write_text(json.dumps(meta, indent=2))
    print(json.dumps(meta, indent=2))


if __name__ == "__main__":
    main()
