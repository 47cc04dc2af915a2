"""FLNR's guide network and its weight-blob export (the format read by
`src/nn/blob.rs`; keep the two in step).

    python3 train/unet.py --parity tests/data/nn_parity   # writes .bin (weights) and .vec (test vector)
"""
import argparse
import struct

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

MAGIC, VERSION = b"LRDN", 3
LEAKY = 0.01


class UNet(nn.Module):
    """input conv3x3 + conv1x1; L encoder blocks (conv3x3, conv3x3 stride 2);
    L decoder blocks (nearest x2, crop, concat skip, two conv3x3); output
    conv3x3 + conv1x1 + sigmoid. LeakyReLU(0.01) after every conv but the last."""

    def __init__(self, cin, cout, widths):
        super().__init__()
        c = list(widths)
        self.cin, self.cout, self.widths = cin, cout, c
        L = len(c) - 1
        self.inp = nn.ModuleList([nn.Conv2d(cin, c[0], 3, padding=1), nn.Conv2d(c[0], c[0], 1)])
        self.enc = nn.ModuleList(
            [nn.ModuleList([nn.Conv2d(c[l - 1], c[l], 3, padding=1), nn.Conv2d(c[l], c[l], 3, stride=2, padding=1)]) for l in range(1, L + 1)]
        )
        self.dec = nn.ModuleList(
            [nn.ModuleList([nn.Conv2d(c[l] + c[l - 1], c[l - 1], 3, padding=1), nn.Conv2d(c[l - 1], c[l - 1], 3, padding=1)]) for l in range(L, 0, -1)]
        )
        self.out = nn.ModuleList([nn.Conv2d(c[0], c[0], 3, padding=1), nn.Conv2d(c[0], cout, 1)])

    def convs(self):
        """The convolutions in the blob's order."""
        yield from self.inp
        for e in self.enc:
            yield from e
        for d in self.dec:
            yield from d
        yield from self.out

    def forward(self, x):
        a = F.leaky_relu(self.inp[0](x), LEAKY)
        h = F.leaky_relu(self.inp[1](a), LEAKY)
        skips = [h]
        for c1, c2 in self.enc:
            h = F.leaky_relu(c2(F.leaky_relu(c1(h), LEAKY)), LEAKY)
            skips.append(h)
        L = len(self.enc)
        for i, (c1, c2) in enumerate(self.dec):
            s = skips[L - 1 - i]
            u = F.interpolate(h, scale_factor=2, mode="nearest")[:, :, : s.shape[2], : s.shape[3]]
            h = F.leaky_relu(c2(F.leaky_relu(c1(torch.cat([u, s], 1)), LEAKY)), LEAKY)
        h = F.leaky_relu(self.out[0](h), LEAKY)
        return torch.sigmoid(self.out[1](h))

    def round_to_f16(self):
        """Round every parameter to f16 (what the blob stores), in place."""
        with torch.no_grad():
            for p in self.parameters():
                p.copy_(p.half().float())


def export(model, path, sigmas=(12.0,), eps=(1e-3, 1e-2), ao_offset=0.0):
    """Writes the blob (version 3): the FLR trained with the network is one
    Gaussian window (one σ) or the adaptive window (three σ), plus ε, ϵ and the
    AO demodulation's offset c (0: off)."""
    assert len(sigmas) in (1, 3) and list(sigmas) == sorted(sigmas)
    payload = []
    for conv in model.convs():
        payload.append(conv.weight.detach().numpy().astype(np.float16).ravel())
        payload.append(conv.bias.detach().numpy().astype(np.float16).ravel())
    payload = np.concatenate(payload)
    c = model.widths
    head = MAGIC + struct.pack("<4I", VERSION, model.cin, model.cout, len(c) - 1)
    head += struct.pack(f"<{len(c)}I", *c) + struct.pack("<I", len(sigmas)) + struct.pack(f"<{len(sigmas)}f", *sigmas) + struct.pack("<2f", *eps) + struct.pack("<f", ao_offset) + struct.pack("<I", payload.size)
    with open(path, "wb") as f:
        f.write(head + payload.astype("<f2").tobytes())


def load_blob(model, path, widen=False):
    """Loads a blob's weights (version 1, 2 or 3) into `model` (same shapes; with `widen`,
    a blob of fewer input planes fills the first ones, the others start at zero weight);
    returns the FLR it was trained with as (sigmas, eps, ao_offset)."""
    b = open(path, "rb").read()
    assert b[:4] == MAGIC, "not an lrdenoise network"
    version, cin, cout, levels = struct.unpack_from("<4I", b, 4)
    assert cout == model.cout and (cin == model.cin or widen and cin < model.cin), "input or output planes differ"
    pos = 20 + 4 * (levels + 1)
    assert list(struct.unpack_from(f"<{levels + 1}I", b, 20)) == list(model.widths), "widths differ"
    if version == 1:
        sigmas, pos = struct.unpack_from("<f", b, pos), pos + 4
    else:
        (k,) = struct.unpack_from("<I", b, pos)
        sigmas, pos = struct.unpack_from(f"<{k}f", b, pos + 4), pos + 4 + 4 * k
    eps, pos = struct.unpack_from("<2f", b, pos), pos + 8
    ao_offset = 0.0
    if version >= 3:
        (ao_offset,), pos = struct.unpack_from("<f", b, pos), pos + 4
    (n,) = struct.unpack_from("<I", b, pos)
    payload = np.frombuffer(b, dtype="<f2", count=n, offset=pos + 4).astype(np.float32)
    at = 0
    with torch.no_grad():
        for i, conv in enumerate(model.convs()):
            for t in (conv.weight, conv.bias):
                if i == 0 and t is conv.weight and cin < model.cin:
                    shape = (t.shape[0], cin) + tuple(t.shape[2:])
                    t.zero_()
                    t[:, :cin] = torch.from_numpy(payload[at : at + int(np.prod(shape))].reshape(shape))
                    at += int(np.prod(shape))
                    continue
                t.copy_(torch.from_numpy(payload[at : at + t.numel()].reshape(t.shape)))
                at += t.numel()
    assert at == n, "payload size differs"
    return sigmas, eps, ao_offset


def write_vector(path, x, y):
    """Test vector: "LRDT", u32 w, h, cin, cout, f32 input planes, f32 output planes."""
    _, cin, h, w = x.shape
    cout = y.shape[1]
    with open(path, "wb") as f:
        f.write(b"LRDT" + struct.pack("<4I", w, h, cin, cout))
        f.write(x.numpy().astype("<f4").tobytes() + y.numpy().astype("<f4").tobytes())


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--parity", required=True, help="path prefix: writes PREFIX.bin and PREFIX.vec")
    ap.add_argument("--widths", default="4,8,12")
    ap.add_argument("--size", default="23x19", help="odd sizes exercise the crops")
    args = ap.parse_args()
    torch.manual_seed(1)
    widths = [int(v) for v in args.widths.split(",")]
    model = UNet(8, 8, widths)
    # larger weights than the default init, so every layer matters in the output
    with torch.no_grad():
        for p in model.parameters():
            p.mul_(2.0)
    model.round_to_f16()
    w, h = (int(v) for v in args.size.split("x"))
    x = torch.rand(1, 8, h, w) * 2 - 0.5
    with torch.no_grad():
        y = model(x)
    export(model, args.parity + ".bin")
    write_vector(args.parity + ".vec", x[0:1], y[0:1])
    print(f"wrote {args.parity}.bin/.vec: widths {widths}, {sum(p.numel() for p in model.parameters())} parameters, output range {y.min():.3f}..{y.max():.3f}")


if __name__ == "__main__":
    main()
