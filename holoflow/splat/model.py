"""GaussianModel: the optimisable parameters of a 3DGS scene, stored before activation."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from holoflow.splat.project import SH_C0


@dataclass
class GaussianModel:
    """Parameters (float32 leaf tensors, requires_grad):
    means [N, 3] world metres; log_scales [N, 3] (scale = exp); quats [N, 4] (w, x, y, z), not
    necessarily normalised; opacity_logits [N] (opacity = sigmoid); sh_dc [N, 1, 3] and
    sh_rest [N, K - 1, 3] SH coefficients, K = (sh_degree + 1)^2; rgb = SH_C0 * dc + 0.5 at degree 0."""

    means: torch.Tensor
    log_scales: torch.Tensor
    quats: torch.Tensor
    opacity_logits: torch.Tensor
    sh_dc: torch.Tensor
    sh_rest: torch.Tensor
    sh_degree: int = 0

    PARAMS = ("means", "log_scales", "quats", "opacity_logits", "sh_dc", "sh_rest")

    def __post_init__(self):
        for name in self.PARAMS:
            t = getattr(self, name).detach().to(torch.float32).contiguous()
            setattr(self, name, t.requires_grad_(True))

    @property
    def sh(self) -> torch.Tensor:
        """All SH coefficients [N, K, 3] (``sh_dc`` itself at degree 0: no copy, the same gradient)."""
        if self.sh_rest.shape[1] == 0:
            return self.sh_dc
        return torch.cat([self.sh_dc, self.sh_rest], 1)

    def __len__(self) -> int:
        return self.means.shape[0]

    def params(self) -> dict[str, torch.Tensor]:
        return {name: getattr(self, name) for name in self.PARAMS}

    def to(self, device: str | torch.device) -> "GaussianModel":
        """The same Gaussians as fresh leaf tensors on ``device`` (cpu, cuda)."""
        return GaussianModel(**{k: getattr(self, k).detach().to(device) for k in self.PARAMS}, sh_degree=self.sh_degree)

    @classmethod
    def from_points(
        cls, xyz, rgb, sh_degree: int = 0, opacity: float = 0.1, scales=None, quats=None
    ) -> "GaussianModel":
        """Init from a coloured point cloud (3DGS recipe): xyz [N, 3] metres, rgb [N, 3] in [0, 1];
        isotropic scale = RMS distance to the 3 nearest neighbours (>= 1e-7 ** 0.5), identity
        rotation, opacity 0.1, SH DC from rgb, higher SH bands zero. ``scales`` [N, 3] (metres) and
        ``quats`` [N, 4] given together replace the neighbour scales and the identity rotation
        (e.g. each point's pixel footprint, holoflow.geometry.area.footprint_gaussians)."""
        from scipy.spatial import cKDTree

        xyz = np.asarray(xyz, np.float64).reshape(-1, 3)
        rgb = np.asarray(rgb, np.float64).reshape(-1, 3)
        if len(rgb) != len(xyz):
            raise ValueError(f"from_points: {len(xyz)} points but {len(rgb)} colours")
        if not 0 <= sh_degree <= 3:
            raise ValueError(f"from_points: sh_degree {sh_degree} not in 0..3")
        n = len(xyz)
        if (scales is None) != (quats is None):
            raise ValueError("from_points: give scales and quats together")
        if scales is not None:
            log_scales = torch.log(torch.as_tensor(scales, dtype=torch.float64).reshape(n, 3).clamp_min(1e-12))
            rot = torch.as_tensor(quats, dtype=torch.float64).reshape(n, 4)
        else:
            d2 = np.full(n, 1e-2)
            if n >= 2:
                dist, _ = cKDTree(xyz).query(xyz, k=min(4, n))  # [N, k], column 0 = self
                d2 = np.maximum((dist[:, 1:] ** 2).mean(1), 1e-7)
            log_scales = torch.from_numpy(np.repeat(0.5 * np.log(d2)[:, None], 3, 1))
            rot = torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1)
        K = (sh_degree + 1) ** 2
        return cls(
            means=torch.from_numpy(xyz),
            log_scales=log_scales,
            quats=rot,
            opacity_logits=torch.full((n,), float(np.log(opacity / (1 - opacity)))),
            sh_dc=torch.from_numpy((rgb - 0.5) / SH_C0)[:, None, :],
            sh_rest=torch.zeros(n, K - 1, 3),
            sh_degree=sh_degree,
        )

    def save_ply(self, path: str | Path) -> None:
        """Write the INRIA 3DGS PLY layout (values before activation; f_rest channel-major)."""
        from holoflow.io.ply import write_gaussians

        with torch.no_grad():
            m = self.to("cpu")
            f = {k: v for k, v in zip("xyz", m.means.T.numpy())}
            f.update({f"f_dc_{i}": m.sh_dc[:, 0, i].numpy() for i in range(3)})
            rest = m.sh_rest.transpose(1, 2).reshape(len(m), -1).numpy()  # [N, 3 (K-1)]
            f.update({f"f_rest_{i}": rest[:, i] for i in range(rest.shape[1])})
            f["opacity"] = m.opacity_logits.numpy()
            f.update({f"scale_{i}": m.log_scales[:, i].numpy() for i in range(3)})
            f.update({f"rot_{i}": m.quats[:, i].numpy() for i in range(4)})
        write_gaussians(path, f)

    @classmethod
    def load_ply(cls, path: str | Path) -> "GaussianModel":
        """Read a 3DGS PLY (SH degree from the f_rest count)."""
        from holoflow.io.ply import read_gaussians

        f = read_gaussians(path)
        n_rest = sum(1 for k in f if k.startswith("f_rest_"))
        K = n_rest // 3 + 1
        deg = int(round(K**0.5)) - 1
        if (deg + 1) ** 2 != K or n_rest % 3:
            raise ValueError(f"{path}: {n_rest} f_rest values do not form SH bands")
        col = lambda names: torch.from_numpy(np.stack([f[k] for k in names], 1))  # noqa: E731
        n = len(f["x"])
        rest = col([f"f_rest_{i}" for i in range(n_rest)]) if n_rest else torch.zeros(n, 0)
        return cls(
            means=col("xyz"),
            log_scales=col([f"scale_{i}" for i in range(3)]),
            quats=col([f"rot_{i}" for i in range(4)]),
            opacity_logits=torch.from_numpy(f["opacity"]),
            sh_dc=col([f"f_dc_{i}" for i in range(3)])[:, None, :],
            sh_rest=rest.reshape(n, 3, K - 1).transpose(1, 2),
            sh_degree=deg,
        )
