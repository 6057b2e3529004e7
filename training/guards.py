"""Resource guards of `train`, checked before any work starts: a fit that cannot fit in memory is refused.

Which guard applies is the model class's declaration (models/capabilities.py): `gp_memory` for an exact GP,
`network` for a minibatch network. An exact GP keeps n×n matrices: `gpr` one per output dimension (its kernel is
per output), `sklearn-gpr` one shared by all outputs. Peak memory, measured on this code (bench: ru_maxrss of a fit,
n up to 4000, O up to 6), declared as each class's `gp_memory`, is the larger of the two phases:
- hyper-parameters on m = min(hyper_points, n) samples: gpr ≈ 11 · m² · O, sklearn ≈ 13 · m² float64 values
  (autograd keeps the kernel, its Cholesky and their gradients; sklearn's gradient is (m, m, Dz + 2));
- conditioning on n = min(max_points, training samples): gpr ≈ 2.7 · n² · O, sklearn ≈ 3.2 · n² values.
A GP over images (O = H·W, 4480 for 56×80) needs terabytes at a few thousand samples; it is refused outright.

A network (mdn, pixel, encoder, multimodal) is counted on PyTorch's meta device (no memory touched): P parameters
and A activation values per sample. Peak of a fit with its checkpoint and float64 inference copy (bench: ru_maxrss,
float32, 1 thread) in float32 values: 9.3–11.6 · P when the weights dominate (pixel fc 4096 and 8192, mdn
2048×2048), 3.0–3.2 · A · batch when the activations do (lean pixel decoder, batch 512 and 1024).
"""

from __future__ import annotations

import math
from pathlib import Path

from bodyschema.base.modalities import is_image
from bodyschema.errors import must_be
from bodyschema.models import kinds
from bodyschema.models.capabilities import GPMemory

# Network fits (float32, Adam): measured copies, rounded up, of the weights at the peak (weights, gradients, Adam's
# two moments, the best weights kept for early stopping, the checkpoint, the float64 inference copy) and of one
# minibatch's activations (kept for the backward pass, their gradients): see the module doc.
PARAM_COPIES = 12.0
ACTIVATION_COPIES = 3.5
LIMIT_FRACTION = 0.8      # of the available memory: leave room for the dataset, Python and the other processes


def gp_memory(kind: str) -> GPMemory | None:
    """The measured memory of kind `kind`'s fit when it is an exact GP (imports its module), else None."""
    return kinds.model_class(kind).gp_memory


def check_config(model: str, modalities: tuple[str, ...]) -> None:
    """Refuse a GP on images before anything is loaded (a GP per pixel cannot fit in any memory)."""
    if any(is_image(m) for m in modalities) and gp_memory(model) is not None:
        raise ValueError(must_be("model", "'pixel' for modality 'image'", f"{model} on image",
                                 "An exact GP keeps an n×n matrix per output, and an image has thousands of "
                                 "outputs (56×80 = 4480): train the pixel decoder, `bodyschema train pixel`."))


def gp_peak_bytes(kind: str, n: int, m: int, outputs: int) -> float:
    """Estimated peak memory (bytes) of a GP fit of kind `kind` on n conditioning and m hyper-parameter samples."""
    return _gp_peak(gp_memory(kind), n, m, outputs)


def _gp_peak(memory: GPMemory, n: int, m: int, outputs: int) -> float:
    per = outputs if memory.per_output else 1
    return 8.0 * per * max(memory.fit_copies * m * m, memory.condition_copies * n * n)


def check_memory(kind: str, model, n_train: int, output_shape: tuple[int, ...],
                 available: float | None = None) -> None:
    """Refuse a fit whose estimated peak exceeds LIMIT_FRACTION of the available memory (`available` bytes;
    None: read from the system): a GP by its n×n matrices, a network by its size and one batch's activations;
    the model's class says which it is (models/capabilities.py)."""
    if model.gp_memory is not None:
        check_gp_memory(kind, model, n_train, output_shape, available)
    elif model.network:
        check_net_memory(model, n_train, available)


def check_gp_memory(kind: str, model, n_train: int, output_shape: tuple[int, ...],
                    available: float | None = None) -> None:
    """Refuse an exact GP whose n×n matrices (model.gp_memory) exceed LIMIT_FRACTION of the available memory."""
    memory, outputs = model.gp_memory, math.prod(output_shape)
    n = min(n_train, int(getattr(model, "max_points", n_train)))
    m = min(n, int(getattr(model, "hyper_points", n)))
    need = _gp_peak(memory, n, m, outputs)
    available = available_memory() if available is None else available
    limit = LIMIT_FRACTION * available
    if need <= limit:
        return
    per = 8.0 * (outputs if memory.per_output else 1)
    fits = int(math.sqrt(limit / (per * max(memory.fit_copies, memory.condition_copies))))
    hint = (f"Train on fewer samples: --max-train {fits} (or --max-points {fits} --hyper-points "
            f"{min(fits, m)})." if fits >= 2 else
            "Even 2 samples do not fit: free memory, or use a kind that fits in mini-batches (`bodyschema train mdn`).")
    raise ValueError(must_be(f"{kind} fit memory", f"at most {limit / 1e9:.3g} GB ({LIMIT_FRACTION:.0%} of the "
                             f"{available / 1e9:.3g} GB available)",
                             f"an estimated {need / 1e9:.3g} GB for n={n} samples × {outputs} outputs "
                             f"(hyper-parameters on m={m})", hint))


def net_sizes(model) -> tuple[int, int]:
    """(parameters, activation values per sample) of the network(s) `model` fits, counted on the meta device:
    nothing is allocated, however large the layers asked for."""
    import torch

    params = activations = 0
    for member in _networks(model):
        with torch.device("meta"):
            net = member._factory()
            params += sum(p.numel() for p in net.parameters())
            activations += _activations_per_sample(getattr(net, "decoder", net), member)   # a member: its decoder
    return params, activations


def _activations_per_sample(net, member) -> int:
    """Values every layer outputs for one sample (the forward pass autograd keeps for the backward one)."""
    import torch

    sizes = []
    hooks = [m.register_forward_hook(lambda _m, _in, out: sizes.append(out.numel()))
             for m in net.modules() if not list(m.children())]
    try:
        shape = member.image_shape if member.encodes else (member.latent_dim,)  # an encoder reads images
        net(torch.zeros(1, *shape, device="meta"))
    finally:
        for hook in hooks:
            hook.remove()
    return sum(sizes)


def net_peak_bytes(params: int, activations: int, batch: int) -> float:
    """Estimated peak memory (bytes) of a float32 network fit with Adam on minibatches of `batch` samples."""
    return 4.0 * (PARAM_COPIES * params + ACTIVATION_COPIES * batch * activations)


def check_net_memory(model, n_train: int, available: float | None = None) -> None:
    """Refuse a network whose weights (with their gradients, Adam's moments, the best weights and the inference
    copies) and one minibatch's activations exceed LIMIT_FRACTION of the available memory."""
    params, activations = net_sizes(model)
    batch = min(n_train, _batch_size(model))
    need = net_peak_bytes(params, activations, batch)
    available = available_memory() if available is None else available
    limit = LIMIT_FRACTION * available
    if need <= limit:
        return
    raise ValueError(must_be("network fit memory", f"at most {limit / 1e9:.3g} GB ({LIMIT_FRACTION:.0%} of the "
                             f"{available / 1e9:.3g} GB available)",
                             f"an estimated {need / 1e9:.3g} GB for {params:,} parameters and {activations:,} "
                             f"activations per sample × batch {batch}",
                             "Ask for a smaller network (--channels, --fc-hidden, --hidden) or a smaller "
                             "--batch-size."))


def _batch_size(model) -> int:
    return max(m.settings.batch_size for m in _networks(model))


def _networks(model) -> list:
    """The networks `model` fits: its members' (multimodal) or its own."""
    return list(model.members.values()) if model.has_members else [model]


def available_memory() -> float:
    """Bytes this process may still allocate: MemAvailable, capped by the cgroup (container) limit if any."""
    values = [_meminfo_available()]
    cgroup = _cgroup_room()
    if cgroup is not None:
        values.append(cgroup)
    known = [v for v in values if v is not None]
    return float(min(known)) if known else math.inf


def _meminfo_available() -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def _cgroup_room() -> int | None:
    """cgroup v2 memory.max − memory.current of this process's cgroup; None when unlimited or unknown."""
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        current = int(Path("/sys/fs/cgroup/memory.current").read_text().strip())
    except (OSError, ValueError):
        return None
    return None if limit == "max" else max(int(limit) - current, 0)
