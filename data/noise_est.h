/* noise_est.h — the Gaussian noise level of a raw coded frame, estimated from the frame. */
#ifndef LM_NOISE_EST_H
#define LM_NOISE_EST_H
/* Standard deviation of additive white Gaussian noise in a raw coded frame (H x W, row-major,
 * one LED per pixel by the tile phase (y mod th, x mod tw)), in the frame's units; < 0 on bad
 * input. */
float lm_noise_estimate(const float *raw, int height, int width, int tile_h, int tile_w);
#endif
