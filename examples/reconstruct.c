/* reconstruct.c — the Lumosaic C API end to end: read a spectral cube, simulate the coded
 * frame the camera would record, reconstruct the cube from that frame with a trained model,
 * and print how close it came (PSNR, SSIM, MAE, SAM).
 *
 *   cc reconstruct.c $(pkg-config --cflags --libs lumosaic) -o reconstruct
 *   ./reconstruct MODEL CUBE [NOISE] [OUT.exr]
 *
 * MODEL: a .safetensors file written by `lumosaic train` (e.g. the bundled
 * models/demo/rt16nc-lmmse.safetensors); CUBE: a CAVE folder, .mat or spectral .exr with 31
 * bands 400-700 nm; NOISE: Gaussian noise level of the simulated frame (default 0; 0.05 =
 * 5 % of its maximum); OUT.exr: where to write the reconstruction (optional). */
#include <stdio.h>
#include <stdlib.h>
#include <lumosaic.h>

static int fail(const char *what, const lm_api_error *err)
{
    fprintf(stderr, "reconstruct: %s: %s\n", what, err->message);
    return 1;
}

int main(int argc, char **argv)
{
    if (argc < 3) {
        fprintf(stderr, "usage: %s MODEL CUBE [NOISE] [OUT.exr]\n", argv[0]);
        return 2;
    }
    lm_api_error err;
    lm_api_model *model = NULL;
    lm_api_system *sys = NULL;
    lm_api_cube *read = NULL, *truth = NULL, *recon = NULL;
    float *frame = NULL;
    int rc = 1, bands, height, width, tr, tc;
    printf("Lumosaic C API %s\n", lm_api_version(NULL, NULL, NULL));
    if (lm_api_model_load(argv[1], NULL, &model, &err)) return fail("model", &err);
    if (lm_api_system_load(NULL, &sys, &err)) { fail("system", &err); goto done; }
    if (lm_api_cube_read(argv[2], NULL, &read, &err)) { fail("cube", &err); goto done; }

    /* The frame must be a whole number of mosaic tiles: crop the cube to them. */
    lm_api_system_info(sys, NULL, &tr, &tc, NULL);
    lm_api_cube_shape(read, &bands, &height, &width, NULL);
    if (bands != 31) {
        fprintf(stderr, "reconstruct: %s has %d bands: this example takes 31 (400-700 nm)\n",
                argv[2], bands);
        goto done;
    }
    height -= height % tr;
    width -= width % tc;
    if (lm_api_cube_crop(read, 0, 0, height, width, &truth, &err)) { fail("crop", &err); goto done; }

    /* The coded frame (bucket 1), with Gaussian noise if asked for. */
    size_t n = (size_t)height * width;
    lm_api_noise noise = {0};
    noise.gauss_k = argc > 3 ? atof(argv[3]) : 0.0;
    frame = malloc(sizeof(float) * n);
    if (!frame) goto done;
    if (lm_api_simulate(sys, truth, &noise, 1, 0, frame, NULL, n, &err)) {
        fail("simulate", &err);
        goto done;
    }

    /* Back to 31 bands: the model estimates the frame's noise level itself. */
    lm_api_frame f = {height, width, LM_API_PIXEL_F32, frame, NULL};
    if (lm_api_reconstruct_cube(model, &f, &recon, &err)) { fail("reconstruct", &err); goto done; }

    lm_api_metrics m;
    if (lm_api_metrics_compute(lm_api_cube_data(recon), lm_api_cube_data(truth), 31, height,
                               width, &m, &err)) {
        fail("metrics", &err);
        goto done;
    }
    const char *preset;
    lm_api_model_info(model, &preset, NULL, NULL, NULL, NULL);
    printf("%s, %d x %d, noise %g: PSNR %.2f dB, SSIM %.4f, MAE %.4f, SAM %.2f deg\n", preset,
           width, height, noise.gauss_k, m.psnr, m.ssim, m.mae, m.sam);
    if (argc > 4 && lm_api_cube_write(argv[4], recon, &err)) { fail("write", &err); goto done; }
    rc = 0;
done:
    free(frame);
    lm_api_cube_free(recon);
    lm_api_cube_free(truth);
    lm_api_cube_free(read);
    lm_api_system_free(sys);
    lm_api_model_free(model);
    return rc;
}
