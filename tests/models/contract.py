"""The SensoryModel contract every model's test inherits (as gpytorch's and scikit-learn's common checks).

A concrete test implements only the factories:
    make_model(seed: int) -> fitted model (same seed → same model)
    make_inputs(n: int, dtype) -> (n, Dz) joint angles in rad inside the model's range
    make_unfitted_model() -> model before fit (raise NotImplementedError when the kind has no fit)
and inherits every check below. Checks run in float64 so finite differences are meaningful.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
import torch

from bodyschema.errors import NotFittedError

FD_STEP = 1e-6            # rad; central differences in float64
FD_RTOL = 1e-4            # relative Jacobian error allowed against finite differences
PRECISION_FD_STEP = 1e-3  # rad; a GP's Π = 1/(s − ‖L⁻¹k‖²) cancels digits: a smaller step differences rounding noise
PRECISION_FD_RTOL = 1e-3
FRESH_PROCESS_RTOL = 1e-12  # float64 results summed in another order (kernel choice, thread split): see the test
_FITTED: dict[type, object] = {}   # one fitted model per concrete test class


class SensoryModelContract:
    batch = 5
    fd_rtol = FD_RTOL
    fd_step = FD_STEP          # a model whose float64 prediction carries more rounding noise takes a larger step

    # ---- factories (override) -----------------------------------------------------------------------
    def make_model(self, seed: int):
        raise NotImplementedError

    def make_inputs(self, n: int, dtype=torch.float64) -> torch.Tensor:
        raise NotImplementedError

    def make_unfitted_model(self):
        raise NotImplementedError

    # ---- cached model: fitting can be slow, the checks only read it --------------------------------
    @pytest.fixture
    def model(self):
        if type(self) not in _FITTED:
            _FITTED[type(self)] = self.make_model(seed=0)
        return _FITTED[type(self)]

    # ---- shapes, dtypes ------------------------------------------------------------------------------
    @pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
    def test_shapes_and_dtypes(self, model, dtype):
        z = self.make_inputs(self.batch, dtype)
        out, dz = model.output_shape, model.latent_dim
        n_out = int(torch.tensor(out).prod())
        assert model.predict(z).shape == (self.batch, *out) and model.predict(z).dtype == dtype
        assert model.jacobian(z).shape == (self.batch, n_out, dz) and model.jacobian(z).dtype == dtype
        assert model.precision(z).shape == (self.batch, *out) and model.precision(z).dtype == dtype
        assert (model.precision(z) > 0).all(), "precision must be positive"
        v = torch.ones(self.batch, *out, dtype=dtype)
        assert model.vjp(z, v).shape == (self.batch, dz) and model.vjp(z, v).dtype == dtype

    # ---- derivatives -----------------------------------------------------------------------------------
    def test_jacobian_matches_central_finite_differences(self, model):
        z = self.make_inputs(self.batch, torch.float64)
        jac = model.jacobian(z)                                        # (B, O, Dz)
        columns = []
        for d in range(model.latent_dim):
            step = torch.zeros_like(z)
            step[:, d] = self.fd_step
            diff = (model.predict(z + step) - model.predict(z - step)) / (2 * self.fd_step)
            columns.append(diff.reshape(self.batch, -1))
        fd = torch.stack(columns, dim=-1)                              # (B, O, Dz)
        rel = (jac - fd).norm() / fd.norm().clamp_min(1e-12)
        assert rel < self.fd_rtol, f"Jacobian differs from finite differences: relative error {rel:.2e}"

    def test_precision_vjp_matches_central_finite_differences(self, model):
        # (∂Π/∂z)ᵀ v: what makes ∂F/∂μ the gradient of F when Π depends on z (zero for a constant Π).
        z = self.make_inputs(self.batch, torch.float64)
        gen = torch.Generator().manual_seed(2)
        v = torch.randn(self.batch, *model.output_shape, generator=gen, dtype=torch.float64)
        fd = torch.zeros_like(z)
        for d in range(model.latent_dim):
            step = torch.zeros_like(z)
            step[:, d] = PRECISION_FD_STEP
            dpi = (model.precision(z + step) - model.precision(z - step)) / (2 * PRECISION_FD_STEP)   # (B, *out)
            fd[:, d] = (dpi * v).reshape(self.batch, -1).sum(-1)
        got = model.precision_vjp(z, v)
        assert got.shape == z.shape and got.dtype == z.dtype
        rel = (got - fd).norm() / fd.norm().clamp_min(1e-12)
        assert rel < PRECISION_FD_RTOL or (got - fd).norm() < 1e-9, f"precision VJP off by {rel:.2e} (relative)"

    def test_vjp_equals_jacobian_transpose_times_v(self, model):
        z = self.make_inputs(self.batch, torch.float64)
        gen = torch.Generator().manual_seed(1)
        v = torch.randn(self.batch, *model.output_shape, generator=gen, dtype=torch.float64)
        expected = torch.einsum("bod,bo->bd", model.jacobian(z), v.reshape(self.batch, -1))
        torch.testing.assert_close(model.vjp(z, v), expected, rtol=1e-8, atol=1e-10)

    # ---- batching, determinism, persistence ---------------------------------------------------------
    def test_rows_are_independent(self, model):
        z = self.make_inputs(self.batch, torch.float64)
        batched = model.predict(z)
        for i in range(self.batch):
            torch.testing.assert_close(model.predict(z[i:i + 1])[0], batched[i], rtol=1e-9, atol=1e-9)
        torch.testing.assert_close(model.jacobian(z[2:3])[0], model.jacobian(z)[2], rtol=1e-9, atol=1e-9)

    def test_same_seed_gives_same_model(self, model):
        z = self.make_inputs(self.batch, torch.float64)
        again = self.make_model(seed=0)
        torch.testing.assert_close(again.predict(z), model.predict(z), rtol=0, atol=0)

    def test_save_then_load_in_process_gives_bit_identical_outputs(self, model, tmp_path):
        # Same process, same threads, same kernels: the loaded tensors must give the very same bits.
        z = self.make_inputs(self.batch, torch.float64)
        model.save(tmp_path / "model")
        loaded = type(model).load(tmp_path / "model")
        for name in ("predict", "jacobian", "precision"):
            torch.testing.assert_close(getattr(loaded, name)(z), getattr(model, name)(z), rtol=0, atol=0, msg=name)
        assert loaded.body == model.body

    def test_save_then_load_in_fresh_process_gives_the_same_outputs(self, model, tmp_path):
        # A fresh process may pick another kernel or thread split for a float64 convolution or matrix product and
        # so sum in another order (seen: 9.4e-16 on 187 of 384 pixels). Reordering a sum of K products moves it by
        # at most ~K·2⁻⁵³·Σ|terms|: FRESH_PROCESS_RTOL covers K up to ~10⁴ with margin; bit-identity is checked
        # in-process above. The child runs with the parent's thread count all the same.
        z = self.make_inputs(self.batch, torch.float64)
        model.save(tmp_path / "model")
        torch.save(z, tmp_path / "z.pt")
        script = textwrap.dedent(f"""
            import torch
            torch.set_num_threads({torch.get_num_threads()})
            from bodyschema.models import load_model
            m = load_model({str(tmp_path / 'model')!r})
            z = torch.load({str(tmp_path / 'z.pt')!r})
            torch.save({{"x": m.predict(z), "j": m.jacobian(z), "p": m.precision(z)}}, {str(tmp_path / 'out.pt')!r})
        """)
        subprocess.run([sys.executable, "-c", script], check=True)
        out = torch.load(tmp_path / "out.pt")
        for name, key in (("predict", "x"), ("jacobian", "j"), ("precision", "p")):
            expected = getattr(model, name)(z)
            torch.testing.assert_close(out[key], expected, rtol=FRESH_PROCESS_RTOL,
                                       atol=FRESH_PROCESS_RTOL * float(expected.abs().max()), msg=name)

    # ---- bad input --------------------------------------------------------------------------------------
    def test_wrong_latent_dim_raises(self, model):
        z = torch.zeros(2, model.latent_dim + 1, dtype=torch.float64)
        with pytest.raises(ValueError, match=r"z must be of shape"):
            model.predict(z)

    def test_missing_batch_axis_raises(self, model):
        with pytest.raises(ValueError, match=r"z must be of shape"):
            model.jacobian(self.make_inputs(1)[0])

    @pytest.mark.parametrize("bad", [float("nan"), float("inf")])
    def test_non_finite_input_raises(self, model, bad):
        z = self.make_inputs(2).clone()
        z[1, 0] = bad
        with pytest.raises(ValueError, match=r"z must be finite"):
            model.predict(z)

    def test_integer_or_list_input_raises(self, model):
        with pytest.raises(TypeError, match=r"z.dtype must be"):
            model.predict(torch.zeros(2, model.latent_dim, dtype=torch.int64))
        with pytest.raises(TypeError, match=r"z.dtype must be"):
            model.predict(np.zeros((2, model.latent_dim), dtype=np.int64))
        with pytest.raises(TypeError, match=r"z must be a torch.Tensor or numpy array"):
            model.predict(self.make_inputs(2).tolist())

    def test_numpy_input_equals_tensor_input(self, model):
        z = self.make_inputs(3)
        v = torch.ones(3, *model.output_shape, dtype=z.dtype)
        torch.testing.assert_close(model.predict(z.numpy()), model.predict(z))
        torch.testing.assert_close(model.jacobian(z.numpy()), model.jacobian(z))
        torch.testing.assert_close(model.vjp(z.numpy(), v.numpy()), model.vjp(z, v))

    def test_vjp_with_wrong_shape_raises(self, model):
        z = self.make_inputs(2)
        with pytest.raises(ValueError, match=r"v must be"):
            model.vjp(z, torch.zeros(3, *model.output_shape, dtype=z.dtype))

    def test_unfitted_model_raises_not_fitted(self):
        try:
            unfitted = self.make_unfitted_model()
        except NotImplementedError:
            pytest.skip("this model kind has no fit step")
        with pytest.raises(NotFittedError):
            unfitted.predict(self.make_inputs(2))
