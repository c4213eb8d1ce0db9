"""torch_twin.py — the PyTorch twin of Lumosaic's reconstruction networks, for the side-by-side
benchmark (bench/vs_torch.py). Each preset is re-expressed layer by layer from models/*.c with the
same parameter names, so the weights of a bench_twin dump load by name; the demosaic front is
the phase-aware bilinear of tensor/ops/mosaic_upsample.c (system.md §6) and the frame fold is the
window scheme of infer/tile.c (system.md §8).

Modes (one per process, like bench_twin; one JSON object on stdout):
  check  --dump F   load F (from `bench_twin --mode dump`), run the same batch, print the
                    norm-wise relative differences of output, loss, every gradient, frame fold
  step              forward, L1, backward, Adam at batch B of 66 x 64 (timed)
  forward           no-grad forward at batch B (timed)
  frame             one H x W frame through the window fold, batch of windows (timed)
The mosaic (tile phases, LED responses) is read from --dump in every mode, so both sides use the
same network front; torch is only a dependency of this benchmark, never of Lumosaic.
What it is not: a training framework or a reference for the C tests.
"""
import argparse
import json
import math
import struct
import sys
import time

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

PH, PW, OUT = 66, 64, 33


# ---- safetensors (F32 only), no extra dependency -----------------------------------------
def load_safetensors(path, prefixes=None):
    """name -> float32 tensor; only names starting with one of `prefixes` when given."""
    out = {}
    with open(path, "rb") as f:
        n = struct.unpack("<Q", f.read(8))[0]
        header = json.loads(f.read(n))
        for k, v in header.items():
            if k == "__metadata__" or (prefixes and not k.startswith(tuple(prefixes))):
                continue
            assert v["dtype"] == "F32", k
            a, b = v["data_offsets"]
            f.seek(8 + n + a)
            arr = np.frombuffer(f.read(b - a), dtype="<f4").copy()
            out[k] = torch.from_numpy(arr).reshape(v["shape"])
    return out


# ---- shared pieces -------------------------------------------------------------------------
def unshuffle(x, fy, fx):
    """B x C x H x W -> B x (C fy fx) x H/fy x W/fx, channel c*fy*fx + i*fx + j."""
    b, c, h, w = x.shape
    x = x.reshape(b, c, h // fy, fy, w // fx, fx).permute(0, 1, 3, 5, 2, 4)
    return x.reshape(b, c * fy * fx, h // fy, w // fx)


def shuffle(x, fy, fx):
    b, c, h, w = x.shape
    x = x.reshape(b, c // (fy * fx), fy, fx, h, w).permute(0, 1, 4, 2, 5, 3)
    return x.reshape(b, c // (fy * fx), h * fy, w * fx)


def axis_table(n, t, phase):
    """mosaic_upsample.c axis_fill: d = clamp(Y - phase, 0, t (ns-1)), v0 = d // t."""
    ns = n // t
    d = np.clip(np.arange(n) - phase, 0, t * (ns - 1))
    v0 = d // t
    v1 = np.minimum(v0 + 1, ns - 1)
    lam = (d - v0 * t).astype(np.float32) / np.float32(t)
    return torch.from_numpy(v0), torch.from_numpy(v1), torch.from_numpy(lam)


class Mosaic:
    def __init__(self, dump):
        self.ty, self.tx = (int(v) for v in dump["mosaic.tile"].tolist())
        ph = dump["mosaic.phase"].to(torch.int64)
        self.py, self.px = ph[:, 0].tolist(), ph[:, 1].tolist()
        self.nch = len(self.py)
        self.response = dump["mosaic.response"]
        self._tabs = {}

    def tables(self, H, W):
        if (H, W) not in self._tabs:
            self._tabs[(H, W)] = [(axis_table(H, self.ty, self.py[k]), axis_table(W, self.tx, self.px[k]))
                                  for k in range(self.nch)]
        return self._tabs[(H, W)]

    def demosaic(self, raw):
        """raw B x 1 x H x W -> B x nch x H x W, phase-aware bilinear (system.md §6)."""
        H, W = raw.shape[2], raw.shape[3]
        chans = []
        for k, ((r0, r1, ly), (c0, c1, lx)) in enumerate(self.tables(H, W)):
            s = raw[:, 0, self.py[k]::self.ty, self.px[k]::self.tx]           # B x hs x ws
            a = s[:, :, c0] * (1 - lx) + s[:, :, c1] * lx                        # B x hs x W
            chans.append(a[:, r0, :] * (1 - ly)[:, None] + a[:, r1, :] * ly[:, None])
        return torch.stack(chans, 1)

    def response_map(self, H, W):
        """1 x 33 x H x W: each pixel's LED response, normalised by the global max (srnet.c)."""
        inv = 1.0 / float(self.response.max()) if float(self.response.max()) > 0 else 1.0
        chan_of = [0] * (self.ty * self.tx)
        for k in range(self.nch):
            chan_of[self.py[k] * self.tx + self.px[k]] = k
        idx = torch.tensor([[chan_of[(y % self.ty) * self.tx + x % self.tx] for x in range(W)]
                            for y in range(H)])
        return (self.response[idx] * inv).permute(2, 0, 1).unsqueeze(0).contiguous()


def conv(ci, co, k, s=1, p=0, g=1, bias=True):
    return nn.Conv2d(ci, co, k, s, p, groups=g, bias=bias)


def conv3(ci, co):
    return nn.Conv2d(ci, co, 3, 1, 1)


# ---- linear baseline (linear.c) ------------------------------------------------------------
class Linear(nn.Module):
    def __init__(self, mo):
        super().__init__()
        self.mo = mo
        self.proj = conv(mo.nch, OUT, 1)

    def forward(self, raw):
        return self.proj(self.mo.demosaic(raw))


# ---- HAN (han.c) ---------------------------------------------------------------------------
class CALayer(nn.Module):
    def __init__(self, C, r):
        super().__init__()
        self.conv_du = nn.Sequential(conv(C, C // r, 1), nn.ReLU(), conv(C // r, C, 1), nn.Sigmoid())

    def forward(self, x):
        return x * self.conv_du(x.mean((2, 3), keepdim=True))


class RCAB(nn.Module):
    def __init__(self, C, r):
        super().__init__()
        self.body = nn.Sequential(conv3(C, C), nn.ReLU(), conv3(C, C), CALayer(C, r))

    def forward(self, x):
        return self.body(x) + x


class ResidualGroup(nn.Module):
    def __init__(self, C, r, nb):
        super().__init__()
        self.body = nn.Sequential(*[RCAB(C, r) for _ in range(nb)], conv3(C, C))

    def forward(self, x):
        return self.body(x) + x


class LAM(nn.Module):
    def __init__(self):
        super().__init__()
        self.gamma = nn.Parameter(torch.zeros(1))

    def forward(self, stack, n):
        B, _, H, W = stack.shape
        f = stack.reshape(B, n, -1)
        a = torch.softmax(-torch.bmm(f, f.transpose(1, 2)), -1)   # = softmax(rowmax - E)
        out = self.gamma * torch.bmm(a, f) + f
        return out.reshape(B, -1, H, W)


class CSAM(nn.Module):
    def __init__(self):
        super().__init__()
        self.conv = nn.Conv3d(1, 1, 3, 1, 1)
        self.gamma = nn.Parameter(torch.zeros(1))

    def forward(self, x):
        z = torch.sigmoid(self.conv(x.unsqueeze(1))).squeeze(1)
        return x * (self.gamma * z) + x


class HAN(nn.Module):
    def __init__(self, mo, G, nb, C, r):
        super().__init__()
        self.mo, self.G = mo, G
        self.head = nn.Sequential(conv3(mo.nch, C))
        self.body = nn.ModuleList([ResidualGroup(C, r, nb) for _ in range(G)] + [conv3(C, C)])
        self.csa = CSAM()
        self.la = LAM()
        self.last_conv = conv3((G + 1) * C, C)
        self.last = conv3(2 * C, C)
        self.tail = nn.Sequential(nn.Identity(), conv3(C, OUT))

    def forward(self, raw):
        x0 = self.head(self.mo.demosaic(raw))
        r, outs = x0, []
        for m in self.body:
            r = m(r)
            outs.insert(0, r)                                          # newest first
        o2 = self.last_conv(self.la(torch.cat(outs, 1), self.G + 1))
        o1 = self.csa(r)
        return self.tail(self.last(torch.cat([o1, o2], 1)) + x0)


# ---- MCAN (mcan.c) -------------------------------------------------------------------------
class MA(nn.Module):
    """Mosaic attention: space-to-channel by the tile, squeeze-excite per (channel, phase)."""
    def __init__(self, cp, ty, tx, red=4):
        super().__init__()
        self.fc = nn.Sequential(nn.Linear(cp, cp // red, bias=False), nn.ReLU(),
                                nn.Linear(cp // red, cp, bias=False), nn.Sigmoid())
        self.ty, self.tx = ty, tx

    def forward(self, x):
        u = unshuffle(x, self.ty, self.tx)
        s = self.fc(u.mean((2, 3)))
        return shuffle(u * s[:, :, None, None], self.ty, self.tx)


class FrontMA(nn.Module):      # official naming "convt_br1_front.0.se"
    def __init__(self, cp, ty, tx):
        super().__init__()
        self.se = MA(cp, ty, tx)

    def forward(self, x):
        return self.se(x)


class CABlock(nn.Module):
    def __init__(self, F_, P, ty, tx):
        super().__init__()
        self.cov_block = nn.Sequential(conv3(F_, F_), nn.LeakyReLU(0.2), conv3(F_, F_),
                                       nn.LeakyReLU(0.2), conv3(F_, F_))
        self.ma = MA(P * F_, ty, tx)

    def forward(self, f):
        return F.leaky_relu(self.ma(self.cov_block(f)) + f, 0.2)


class Back(nn.Module):
    def __init__(self, F_):
        super().__init__()
        self.cov_block = nn.Sequential(nn.Conv2d(F_, OUT, 3, 1, 1))


class P2W(nn.Module):
    def __init__(self, P):
        super().__init__()
        self.meta_block = nn.Sequential(nn.Linear(2, 128), nn.ReLU(), nn.Linear(128, 25 * P))


class MCAN(nn.Module):
    def __init__(self, mo, F_):
        super().__init__()
        self.mo, ty, tx = mo, mo.ty, mo.tx
        P = mo.nch
        self.P, self.ty, self.tx = P, ty, tx
        self.WB_Conv = nn.Conv2d(P, P, (2 * ty - 1, 2 * tx - 1), 1, (ty - 1, tx - 1), groups=P, bias=False)
        self.WB_Conv.weight.requires_grad_(False)
        self.WB_lift = conv(P, OUT, 1)
        self.P2W = P2W(P)
        self.convt_br1_front = nn.ModuleList([FrontMA(P * P, ty, tx)])
        self.front_conv_input = conv3(P, F_)
        self.convt_F1 = nn.ModuleList([CABlock(F_, P, ty, tx)])
        self.convt_F2 = nn.ModuleList([CABlock(F_, P, ty, tx)])
        self.convt_br1_back = nn.ModuleList([Back(F_)])
        pos = [((q // tx + 1) / ty, (q % tx + 1) / tx) for q in range(P)]   # tile phase q = i tx + j
        self.register_buffer("pos", torch.tensor(pos, dtype=torch.float32), persistent=False)
        self._masks = {}

    def sparse_mask(self, H, W):
        if (H, W) not in self._masks:
            m = torch.zeros(1, self.P, H, W)
            for k in range(self.P):
                m[0, k, self.mo.py[k]::self.ty, self.mo.px[k]::self.tx] = 1
            self._masks[(H, W)] = m
        return self._masks[(H, W)]

    def mosaic_conv(self, raw):
        """Per-phase 5x5 kernels from the MLP on each pixel's 5x5 neighbourhood."""
        B, _, H, W = raw.shape
        P, h, w = self.P, H // self.ty, W // self.tx
        kw = self.P2W.meta_block(self.pos).reshape(P, 25, P)                  # q x k x o
        cols = F.unfold(raw, 5, padding=2).reshape(B, 25, H, W)
        cols = unshuffle(cols, self.ty, self.tx).reshape(B, 25, P, h, w)       # b k q y x
        out = torch.einsum("bkqyx,qko->boqyx", cols, kw).reshape(B, P * P, h, w)
        return shuffle(out, self.ty, self.tx)

    def forward(self, raw):
        H, W = raw.shape[2], raw.shape[3]
        base = self.WB_lift(self.WB_Conv(raw * self.sparse_mask(H, W)))
        f = F.leaky_relu(self.mosaic_conv(raw), 0.2)
        f = F.leaky_relu(self.convt_br1_front[0](f), 0.2)
        f = self.front_conv_input(f)
        f = self.convt_F2[0](self.convt_F1[0](f))
        return self.convt_br1_back[0].cov_block(f) + base


# ---- SRNet (srnet.c) -----------------------------------------------------------------------
class LNBody(nn.Module):
    def __init__(self, d):
        super().__init__()
        self.weight = nn.Parameter(torch.ones(d))
        self.bias = nn.Parameter(torch.zeros(d))


class LN(nn.Module):
    """Per pixel over channels, biased variance, eps 1e-5."""
    def __init__(self, d):
        super().__init__()
        self.body = LNBody(d)

    def forward(self, x):
        return F.layer_norm(x.permute(0, 2, 3, 1), x.shape[1:2], self.body.weight, self.body.bias,
                            1e-5).permute(0, 3, 1, 2)


class SpecAttn(nn.Module):
    def __init__(self, d, h):
        super().__init__()
        self.h = h
        self.rescale = nn.Parameter(torch.ones(h, 1, 1))
        for n in "qkv":
            setattr(self, "to_" + n, conv(d, d, 1, bias=False))
            setattr(self, n + "_dwconv", conv(d, d, 3, 1, 1, g=d, bias=False))
        self.proj = conv(d, d, 1, bias=False)

    def forward(self, x):
        B, d, H, W = x.shape
        q = self.q_dwconv(self.to_q(x)).reshape(B, self.h, d // self.h, H * W)
        k = self.k_dwconv(self.to_k(x)).reshape(B, self.h, d // self.h, H * W)
        v = self.v_dwconv(self.to_v(x)).reshape(B, self.h, d // self.h, H * W)
        q, k = F.normalize(q, dim=-1, eps=1e-12), F.normalize(k, dim=-1, eps=1e-12)
        a = torch.softmax((q @ k.transpose(-2, -1)) * self.rescale, -1)
        return self.proj((a @ v).reshape(B, d, H, W))


class FFN(nn.Module):
    def __init__(self, d):
        super().__init__()
        self.net1 = nn.Sequential(conv(d, d, 1, bias=False), nn.GELU(), conv(d, d, 3, 1, 1, g=d, bias=False))
        self.net2 = nn.Sequential(conv(d, d, 1, bias=False), nn.GELU(), conv(d, d, 3, 1, 1, g=d, bias=False))
        self.out_conv = conv(2 * d, d, 1, bias=False)

    def forward(self, x):
        return self.out_conv(F.gelu(torch.cat([self.net1(x), self.net2(x)], 1)))


class SAM(nn.Module):
    def __init__(self, d, h):
        super().__init__()
        self.blocks = nn.ModuleList([nn.ModuleList([LN(d), SpecAttn(d, h), LN(d), FFN(d)])])

    def forward(self, x):
        n1, att, n2, ffn = self.blocks[0]
        x = att(n1(x)) + x
        return ffn(n2(x)) + x


class SRNet(nn.Module):
    def __init__(self, mo, d, stages=3, heads=(1, 2, 4, 8)):
        super().__init__()
        self.mo, self.stages = mo, stages
        self.embedding1 = conv(mo.nch, d, 3, 1, 1, bias=False)
        self.embedding2 = conv(mo.response.shape[1], d, 3, 1, 1, bias=False)
        self.embedding = conv(2 * d, d, 3, 1, 1, bias=False)
        self.down_sample = conv(d, d, 4, 2, 1, bias=False)
        self.up_sample = nn.ConvTranspose2d(d, d, 2, 2)
        self.mapping = conv(d, OUT, 3, 1, 1, bias=False)
        enc, dd = [], d
        for i in range(stages):
            enc.append(nn.ModuleList([SAM(dd, heads[i]), conv(dd, 2 * dd, 4, 2, 1, bias=False)]))
            dd *= 2
        self.encoder_layers = nn.ModuleList(enc)
        self.bottleneck = SAM(dd, heads[stages])
        dec = []
        for i in range(stages):
            dec.append(nn.ModuleList([nn.ConvTranspose2d(dd, dd // 2, 2, 2), conv(dd, dd // 2, 1, bias=False),
                                      SAM(dd // 2, heads[stages - 1 - i])]))
            dd //= 2
        self.decoder_layers = nn.ModuleList(dec)
        self._maps = {}

    def forward(self, raw):
        H, W = raw.shape[2], raw.shape[3]
        ph, pw = (16 - H % 16) % 16, (16 - W % 16) % 16
        x = self.mo.demosaic(raw)
        if (H, W) not in self._maps:
            self._maps[(H, W)] = self.mo.response_map(H, W)
        mask = self._maps[(H, W)]
        if ph or pw:
            x = F.pad(x, (0, pw, 0, ph), mode="reflect")
            mask = F.pad(mask, (0, pw, 0, ph), mode="reflect")
        e1 = self.embedding1(x)
        e2 = self.embedding2(mask).expand_as(e1)
        fea = self.embedding(torch.cat([e1, e2], 1))
        residual, skips = fea, []
        fea = self.down_sample(fea)
        for sam, down in self.encoder_layers:
            fea = sam(fea)
            skips.append(fea)
            fea = down(fea)
        fea = self.bottleneck(fea)
        for i, (up, fuse, sam) in enumerate(self.decoder_layers):
            fea = sam(fuse(torch.cat([up(fea), skips[self.stages - 1 - i]], 1)))
        out = self.mapping(self.up_sample(fea) + residual)
        return out[:, :, :H, :W]


PRESETS = {
    "linear": lambda mo: Linear(mo),
    "han-tiny": lambda mo: HAN(mo, 2, 2, 16, 4),
    "han-g3b2c32": lambda mo: HAN(mo, 3, 2, 32, 8),
    "han-small": lambda mo: HAN(mo, 4, 6, 64, 16),
    "han-paper": lambda mo: HAN(mo, 10, 18, 128, 16),
    "mcan-tiny": lambda mo: MCAN(mo, 16),
    "mcan": lambda mo: MCAN(mo, 64),
    "srnet-tiny": lambda mo: SRNet(mo, 8),
    "srnet": lambda mo: SRNet(mo, 32),
}


def build(preset, dump, load_weights=True):
    """The twin of `preset`; with load_weights, every parameter loaded by name from the dump
    (names and shapes must match exactly). Timing modes keep PyTorch's own init instead, so the
    dump's weights do not inflate the twin's peak memory (the time does not depend on values)."""
    mo = Mosaic(dump)
    model = PRESETS[preset](mo)
    if not load_weights:
        return model
    params = {k[len("param."):]: v for k, v in dump.items() if k.startswith("param.")}
    sd = model.state_dict()
    missing = sorted(set(sd) - set(params))
    extra = sorted(set(params) - set(sd))
    if missing or extra:
        raise SystemExit(f"torch_twin: {preset}: parameter names differ: missing in dump "
                         f"{missing[:5]}, not in twin {extra[:5]}")
    for k in sd:
        if tuple(sd[k].shape) != tuple(params[k].shape):
            raise SystemExit(f"torch_twin: {preset}: {k} shape {tuple(sd[k].shape)} vs dump "
                             f"{tuple(params[k].shape)}")
    model.load_state_dict(params, strict=True)
    return model


# ---- the window fold (infer/tile.c) --------------------------------------------------------
def tile_positions(n, win, stride):
    pos = list(range(0, n - win + 1, stride))
    if pos and pos[-1] + win < n:
        pos.append(n - win)
    return pos


def tile_kernel_1d(n, floor=0.05):
    i = np.arange(n, dtype=np.float64)
    return torch.from_numpy((floor + (1 - floor) * np.sin(math.pi * (i + 0.5) / n) ** 2).astype(np.float32))


@torch.no_grad()
def fold(model, frame, batch, win=(PH, PW), stride=(30, 32)):
    """frame H x W -> OUT x H x W: K-weighted average of the window outputs, raster order."""
    H, W = frame.shape
    ys, xs = tile_positions(H, win[0], stride[0]), tile_positions(W, win[1], stride[1])
    K = tile_kernel_1d(win[0])[:, None] * tile_kernel_1d(win[1])[None, :]
    out, wsum = torch.zeros(OUT, H, W), torch.zeros(H, W)
    wins = [(y, x) for y in ys for x in xs]
    for w0 in range(0, len(wins), batch):
        chunk = wins[w0:w0 + batch]
        inp = torch.stack([frame[y:y + win[0], x:x + win[1]] for y, x in chunk]).unsqueeze(1)
        res = model(inp) * K
        for b, (y, x) in enumerate(chunk):
            out[:, y:y + win[0], x:x + win[1]] += res[b]
            wsum[y:y + win[0], x:x + win[1]] += K
    return out / wsum


# ---- modes ---------------------------------------------------------------------------------
def rel(a, b):
    """Norm-wise relative difference ||a - b|| / ||b|| (absolute when b is 0)."""
    a, b = a.double(), b.double()
    nb = float(b.norm())
    d = float((a - b).norm())
    return d / nb if nb > 0 else d


def check(model, dump):
    raw, tgt = dump["raw"], dump["target"]
    model.zero_grad(set_to_none=True)
    grads = any(k.startswith("grad.") for k in dump)
    with torch.set_grad_enabled(grads):
        out = model(raw)
        loss = F.l1_loss(out, tgt)
        if grads:
            loss.backward()
    res = {"out": rel(out.detach(), dump["out"]), "loss": rel(loss.detach().reshape(1), dump["loss"])}
    gr = {}
    named = dict(model.named_parameters())
    for k, v in dump.items():
        if k.startswith("grad."):
            p = named[k[5:]]
            g = p.grad if p.grad is not None else torch.zeros_like(p)
            gr[k[5:]] = rel(g, v)
    if gr:
        worst = max(gr, key=gr.get)
        res["grad_max"], res["grad_worst"], res["grads"] = gr[worst], worst, gr
    if "frame.raw" in dump:
        fr = dump["frame.raw"][0, 0]
        res["frame"] = rel(fold(model, fr, 8), dump["frame.out"][0])
    return res


def timed(args, model):
    g = torch.Generator().manual_seed(7)
    times = []
    if args.mode == "frame":
        frame = torch.rand(args.height, args.width, generator=g)
        model.eval()
        for i in range(args.warmup + args.reps):
            t0 = time.perf_counter()
            fold(model, frame, args.batch)
            if i >= args.warmup:
                times.append(time.perf_counter() - t0)
        return times
    raw = torch.rand(args.batch, 1, PH, PW, generator=g)
    tgt = torch.rand(args.batch, OUT, PH, PW, generator=g)
    if args.mode == "forward":
        with torch.no_grad():
            for i in range(args.warmup + args.reps):
                t0 = time.perf_counter()
                F.l1_loss(model(raw), tgt)
                if i >= args.warmup:
                    times.append(time.perf_counter() - t0)
        return times
    opt = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=1e-4,
                           betas=(0.9, 0.999), eps=1e-8)
    for i in range(args.warmup + args.reps):
        t0 = time.perf_counter()
        opt.zero_grad(set_to_none=True)
        loss = F.l1_loss(model(raw), tgt)
        loss.backward()
        opt.step()
        if i >= args.warmup:
            times.append(time.perf_counter() - t0)
    return times


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--preset", required=True, choices=sorted(PRESETS))
    ap.add_argument("--mode", default="step", choices=["check", "step", "forward", "frame"])
    ap.add_argument("--dump", required=True, help="bench_twin dump (weights, mosaic, batch)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--warmup", type=int, default=1)
    ap.add_argument("--batch", type=int, default=0)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--width", type=int, default=640)
    args = ap.parse_args()
    if args.batch <= 0:
        args.batch = 8 if args.mode == "frame" else 4
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    check_mode = args.mode == "check"
    dump = load_safetensors(args.dump, None if check_mode else ["mosaic."])
    model = build(args.preset, dump, load_weights=check_mode)
    nparams = sum(p.numel() for p in model.parameters() if p.requires_grad)
    base = {"side": "torch", "torch": torch.__version__, "preset": args.preset, "mode": args.mode,
            "threads": torch.get_num_threads(), "batch": args.batch, "params": nparams}
    if check_mode:
        base.update(check(model, dump))
    else:
        t = [1e3 * v for v in timed(args, model)]
        base.update({"times_ms": t, "min_ms": min(t), "median_ms": float(np.median(t))})
        if args.mode == "frame":
            base.update({"height": args.height, "width": args.width})
    print(json.dumps(base))


if __name__ == "__main__":
    sys.exit(main())
