"""A trained network as a model: `NetHolder` holds it (its float32/float64 inference copies, its device, its saved
state; the image encoder is one), and `NetModel` makes it a `BaseSensoryModel`'s g with the autograd derivatives:
Jacobian by forward mode (`vmap(jacfwd)`: Dz JVPs, cheap when outputs ≫ Dz) and a VJP as one backward over the whole
batch. Training the network is `_nn_fit`'s.
"""

from __future__ import annotations

import copy
from typing import Callable

import torch
from torch import nn

from bodyschema.models.capabilities import Capabilities
from bodyschema.models.device import check_device


class NetHolder(Capabilities):
    """Mixin: a trained network `self.net_` (float32) with its dtype copies, its device, and its saved state."""

    network = True                  # the subclass builds it with `_factory()` and fits it with `settings`

    net_: nn.Module | None = None
    device = torch.device("cpu")    # where the network is evaluated (`to`); trained models arrive on the CPU
    compute_dtype = torch.float32   # what inference should feed: the weights' dtype (the float64 copy is for
                                    # derivative checks: ~10× slower on CPU and no more accurate than its weights)

    @property
    def is_fitted(self) -> bool:
        return self.net_ is not None

    def to(self, device: str | torch.device) -> "NetHolder":
        """Evaluate the network on `device` ("cpu", "cuda", "cuda:N") from now on; inputs may stay on any
        device and results come back on the caller's. Learned tensors (`name_`) move along. Returns self."""
        device = check_device(device)
        for name, value in list(vars(self).items()):
            if name.endswith("_") and isinstance(value, torch.Tensor):
                setattr(self, name, value.to(device))
        if self.net_ is not None:
            self._nets = {dtype: net.to(device) for dtype, net in self._nets.items()}
            self.net_ = self._nets[torch.float32]
        self.device = device
        return self

    def _set_net(self, net: nn.Module) -> None:
        net = net.eval().requires_grad_(False).to(self.device)   # inference: no weight gradients in VJP graphs
        self.net_ = net
        self._nets = {torch.float32: net}

    def _net(self, dtype: torch.dtype) -> nn.Module:
        if dtype not in self._nets:   # a float64 copy, so finite-difference checks are meaningful
            self._nets[dtype] = copy.deepcopy(self.net_).to(dtype)
        return self._nets[dtype]

    def _state(self) -> dict[str, torch.Tensor]:
        return {f"net.{k}": v for k, v in self.net_.state_dict().items()}

    def _restore_net(self, factory: Callable[[], nn.Module], state: dict[str, torch.Tensor]) -> None:
        with torch.device("meta"):
            net = factory()
        net = net.to_empty(device="cpu")
        net.load_state_dict({k[4:]: v for k, v in state.items() if k.startswith("net.")})
        self._set_net(net)


class NetModel(NetHolder):
    """Mixin for a `BaseSensoryModel` whose g is a network: the subclass implements `_outputs(net, u)`, u in
    [-1, 1], and gets predict, the Jacobian and the VJP by autograd, on the model's device."""

    def _outputs(self, net: nn.Module, u: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def _g(self, z: torch.Tensor, net: nn.Module | None = None) -> torch.Tensor:
        """g(z) with z in rad, scaled inside so autograd derivatives are w.r.t. rad; evaluated on the model's
        device, returned on z's (the copies are differentiable, and no-ops on one device). # (B, Dz) → (B, *out)"""
        u = self.body.to_unit(z.to(self.device))
        return self._outputs(net or self._net(z.dtype), u).to(z.device)

    def _predict(self, z: torch.Tensor) -> torch.Tensor:
        with torch.no_grad():
            return self._g(z)

    def _jacobian(self, z: torch.Tensor) -> torch.Tensor:
        net = self._net(z.dtype)   # resolved outside the transform: a first float64 call copies the net
        def single(zi):   # (Dz,) → (O,)
            return self._g(zi[None], net).reshape(-1)
        with torch.no_grad():
            return torch.func.vmap(torch.func.jacfwd(single))(z)   # (B, O, Dz)

    def _vjp(self, z: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        with torch.enable_grad():   # one backward for the whole batch: rows are independent
            z = z.detach().requires_grad_(True)
            (grad,) = torch.autograd.grad(self._g(z), z, v)
        return grad   # (B, Dz)

    def predict_and_vjp(self, z: torch.Tensor):
        """g(z) and v ↦ Jᵀv from that same forward pass: an AIF step needs both, so one forward instead of two.
        # (B, Dz) → (B, *out), fn((B, *out)) → (B, Dz)"""
        z = self._check_z(z)
        with torch.enable_grad():
            leaf = z.detach().requires_grad_(True)
            out = self._g(leaf)

        def vjp(v: torch.Tensor) -> torch.Tensor:
            (grad,) = torch.autograd.grad(out, leaf, self._check_v(v, z), retain_graph=True)
            return grad

        return out.detach(), vjp
