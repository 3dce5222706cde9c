"""The segmenter's network: a compact RGB-D U-Net that labels every pixel with a class.

Why semantic segmentation plus instance separation, not a prototype-mask head: the classes
are few, objects of one class rarely touch in these scenes (artifacts stand 0.3 m apart,
people 1.5 m) and where they do, depth separates them; so a per-pixel class map split into
connected components and cut along depth discontinuities (`services.perception.segmenter`)
gives instances with pixel-exact masks for far less compute than boxes, NMS and per-box
masks, and trains from a plain cross-entropy with no anchors or matching.

Input (1, 4, H, W), made by `data.network_input`: RGB normalised by `MEAN`/`STD` and
inverse depth (1/m, clipped at `INV_DEPTH_MAX`, 0 for no return, divided by it): depth
makes silhouettes crisp where colour is ambiguous (a white box on a white table) and is
what sim and real cameras agree on best. Encoder: four stride-2 stages (12, 24, 48, 64
channels; 1/2 … 1/16) and a dilated context block; decoder: upsample, add a 1x1 lateral of
the skip, one 3x3 conv, up to 1/2 resolution, bilinear to full; a full-resolution 3x3
branch on the input joins it in a 1x1 head (a 3x3 there would cost more than the whole
encoder), so mask edges are placed to the pixel. Output: (1, C, H, W) class logits. Only
ops OpenCV's DNN runs fast (conv, batch norm, ReLU, add, concat, bilinear resize).
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

IN_CHANNELS = 4  # RGB and inverse depth: `data.network_input`


def _conv(c_in: int, c_out: int, stride: int = 1, dilation: int = 1) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(c_in, c_out, 3, stride, padding=dilation, dilation=dilation, bias=False),
        nn.BatchNorm2d(c_out),
        nn.ReLU(inplace=True),
    )


class _Up(nn.Module):
    """Upsample ×2, add a 1x1 projection of the skip, one 3x3 conv."""

    def __init__(self, c_in: int, c_skip: int, c_out: int) -> None:
        super().__init__()
        self.reduce = nn.Conv2d(c_in, c_out, 1, bias=False)
        self.lateral = nn.Conv2d(c_skip, c_out, 1, bias=False)
        self.conv = _conv(c_out, c_out)

    def forward(self, x: torch.Tensor, skip: torch.Tensor) -> torch.Tensor:
        x = F.interpolate(self.reduce(x), size=skip.shape[-2:], mode="bilinear")
        return self.conv(x + self.lateral(skip))


class SegNet(nn.Module):
    """Class logits (N, n_classes, H, W) for (N, 4, H, W) normalised RGB-D."""

    def __init__(self, n_classes: int, width: tuple[int, int, int, int] = (12, 24, 48, 64)) -> None:
        super().__init__()
        c1, c2, c3, c4 = width
        self.stem = _conv(IN_CHANNELS, c1, 2)  # 1/2
        self.enc2 = nn.Sequential(_conv(c1, c2, 2), _conv(c2, c2))  # 1/4
        self.enc3 = nn.Sequential(_conv(c2, c3, 2), _conv(c3, c3))  # 1/8
        self.enc4 = nn.Sequential(_conv(c3, c4, 2), _conv(c4, c4))  # 1/16
        self.context = nn.Sequential(_conv(c4, c4, dilation=2), _conv(c4, c4, dilation=4))
        self.up3 = _Up(c4, c3, c3)
        self.up2 = _Up(c3, c2, c2)
        self.up1 = _Up(c2, c1, c1)
        self.full = _conv(IN_CHANNELS, 8)
        self.head = nn.Sequential(
            nn.Conv2d(c1 + 8, 16, 1, bias=False),
            nn.BatchNorm2d(16),
            nn.ReLU(inplace=True),
            nn.Conv2d(16, n_classes, 1),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        s1 = self.stem(x)
        s2 = self.enc2(s1)
        s3 = self.enc3(s2)
        s4 = self.context(self.enc4(s3))
        y = self.up1(self.up2(self.up3(s4, s3), s2), s1)
        y = F.interpolate(y, size=x.shape[-2:], mode="bilinear")
        return self.head(torch.cat([y, self.full(x)], dim=1))
