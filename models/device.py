"""`check_device`: the one parser of a user's device name ("cpu", "cuda", "cuda:N") for training and inference."""

from __future__ import annotations

import re

import torch

from bodyschema.errors import must_be

_NAME = re.compile(r"^(cpu|cuda(:\d+)?)$")
EXPECTED = "'cpu' or an available CUDA device"


def check_device(name: str | torch.device) -> torch.device:
    """The torch.device for `name`; raises the house error for a malformed name or a CUDA device this machine
    does not have (checked here, at the edge, not at the first tensor moved)."""
    text = str(name) if isinstance(name, (str, torch.device)) else None
    if text is None or not _NAME.match(text):
        raise ValueError(must_be("device", f"{EXPECTED} ('cpu', 'cuda' or 'cuda:N')", name))
    device = torch.device(text)
    if device.type == "cpu":
        return device
    if not torch.cuda.is_available():
        raise ValueError(must_be("device", EXPECTED, text, "CUDA is not available on this machine: use --device "
                                                           "cpu (or install a CUDA build of torch)."))
    count = torch.cuda.device_count()
    if device.index is not None and device.index >= count:
        raise ValueError(must_be("device", EXPECTED, text, f"This machine has {count} CUDA device(s): "
                                                           f"cuda:0 … cuda:{count - 1}."))
    return device
