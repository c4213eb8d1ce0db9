"""spectrum.py — Lumosaic from Python, as in a notebook: read a CAVE scene, simulate the coded
frame the camera would record, reconstruct the 31-band cube with the bundled demo model, and
plot one pixel's spectrum against the truth beside the sRGB previews; save the figure.

    pip install ./python matplotlib
    python examples/spectrum.py [SCENE] [OUT.png]

SCENE: a CAVE folder, .mat or spectral .exr with 31 bands 400-700 nm (default: the CAVE scene
../shared/data/cave-256/cd_256 beside this checkout); OUT.png: the figure (default
spectrum.png).
"""
import sys
from pathlib import Path

import matplotlib.pyplot as plt

import lumosaic

repo = Path(__file__).resolve().parent.parent
scene = sys.argv[1] if len(sys.argv) > 1 else repo.parent / "shared/data/cave-256/cd_256"
out = sys.argv[2] if len(sys.argv) > 2 else "spectrum.png"

model = lumosaic.Model(repo / "models/demo/rt16nc-lmmse.safetensors")
truth = lumosaic.read_cube(scene)  # (height, width, 31) reflectance, 400-700 nm

# frames are whole mosaic tiles: crop the scene to them
th, tw = model.tile
h, w = truth.shape[0] // th * th, truth.shape[1] // tw * tw
truth = truth[:h, :w]

frame = lumosaic.simulate(truth, noise=0.05, seed=1)  # the coded frame, 5 % Gaussian noise
cube = model.reconstruct(frame)  # (h, w, 31), the noise level estimated from the frame
score = lumosaic.metrics(cube, truth)
print(f"{model.preset}, {w} x {h}: PSNR {score.psnr:.2f} dB, SSIM {score.ssim:.4f}, "
      f"SAM {score.sam:.2f} deg")

y, x = 140, 200  # the pixel whose spectrum is plotted (the green of the disc's rainbow)
fig, ax = plt.subplots(1, 4, figsize=(16, 4.2), width_ratios=[1, 1, 1, 1.4])
ax[0].imshow(frame, cmap="gray")
ax[0].set_title("coded frame (simulated, 5 % noise)")
ax[1].imshow(lumosaic.srgb(truth))
ax[1].set_title("truth (sRGB)")
ax[2].imshow(lumosaic.srgb(cube))
ax[2].set_title(f"reconstruction (sRGB), {score.psnr:.1f} dB")
for a in ax[:3]:
    a.plot(x, y, "+", color="red", markersize=14, markeredgewidth=2)
    a.set_axis_off()
ax[3].plot(model.wavelengths, truth[y, x], "k-", label="truth")
ax[3].plot(model.wavelengths, cube[y, x], "o--", color="tab:red", label=model.preset)
ax[3].set_xlabel("wavelength (nm)")
ax[3].set_ylabel("reflectance")
ax[3].set_title(f"pixel (x {x}, y {y})")
ax[3].set_ylim(bottom=0)
ax[3].grid(alpha=0.3)
ax[3].legend()
fig.tight_layout()
fig.savefig(out, dpi=90)
print(f"figure: {out}")
