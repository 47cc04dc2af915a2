/* A C99 client of liblrdenoise: builds a synthetic frame, queries sizes,
 * mallocs scratch, runs FLR whole-frame and tiled on WORKERS threads, checks the
 * two agree bit for bit, runs it on half-float buffers (equal to the f32 run on
 * the same values, rounded), exercises error paths, prints the timing, and writes
 * the whole-frame output (raw little-endian f32 RGB) to argv[1] if given. With
 * argv[2] (an FLNR weight blob, e.g. train/flnr.bin) it also runs FLNR.
 *
 *   gcc -std=c99 -Wall -Wextra -Werror -Iffi/include ffi/examples/client.c \
 *       target/release/liblrdenoise.a -lpthread -lm -ldl -o client
 *
 * WORKERS (default 2) is the tiled run's worker count; worker 0 runs on the
 * main thread, so -DWORKERS=1 spawns no thread (as under qemu-user, which
 * hangs in any binary that does).
 */
#define _POSIX_C_SOURCE 200809L
#include "lrdenoise.h"
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#ifndef WORKERS
#define WORKERS 2
#endif

/* Must match synthetic() in ffi/tests/c_client.rs. */
#define W 333
#define H 217

static float hash01(uint32_t x) {
    x ^= x >> 16; x *= 0x7feb352dU; x ^= x >> 15; x *= 0x846ca68bU; x ^= x >> 16;
    return (float)(x >> 8) / 16777216.0f;
}

static void synthetic(float *noisy, float *normal, float *depth, float *ao) {
    for (uint32_t y = 0; y < H; y++) {
        for (uint32_t x = 0; x < W; x++) {
            uint32_t i = y * W + x;
            uint32_t region = (x > W / 3) + 2 * (y > H / 2);
            normal[3 * i + 0] = region == 1 ? 1.0f : 0.0f;
            normal[3 * i + 1] = region == 0 ? 1.0f : 0.0f;
            normal[3 * i + 2] = region >= 2 ? 1.0f : 0.0f;
            depth[i] = 2.0f + 0.01f * (float)y + (float)region;
            ao[i] = 0.5f + 0.5f * hash01(i / 7);
            for (uint32_t c = 0; c < 3; c++) {
                float clean = (0.2f + 0.1f * (float)c + 0.05f * (float)region) * ao[i];
                noisy[3 * i + c] = clean * 2.0f * hash01(i * 3 + c + 12345);
            }
        }
    }
}

static LrdImage image(const float *data, uint32_t channels) {
    LrdImage im;
    memset(&im, 0, sizeof im);
    im.data = data;
    im.format = LRD_FORMAT_F32;
    im.width = W;
    im.height = H;
    im.pixel_stride = channels * sizeof(float); /* interleaved; 0 would mean the same */
    return im;
}

/* IEEE half floats by hand (C99 has no half type): round to nearest, ties to
 * even; the values here are finite and far from f16's overflow. */
static uint16_t to_half(float f) {
    uint32_t x;
    memcpy(&x, &f, sizeof x);
    uint32_t sign = (x >> 16) & 0x8000u, m = x & 0x7fffffu;
    int32_t e = (int32_t)((x >> 23) & 0xffu) - 127 + 15;
    if (e >= 31) return (uint16_t)(sign | 0x7c00u);
    if (e < -10) return (uint16_t)sign;
    uint32_t shift = 13, h;
    if (e <= 0) { /* subnormal half */
        m |= 0x800000u;
        shift = (uint32_t)(14 - e);
        h = m >> shift;
    } else {
        h = ((uint32_t)e << 10) | (m >> 13);
    }
    uint32_t rem = m & ((1u << shift) - 1), tie = 1u << (shift - 1);
    if (rem > tie || (rem == tie && (h & 1u))) h++;
    return (uint16_t)(sign | h);
}

static float from_half(uint16_t h) {
    uint32_t sign = (uint32_t)(h & 0x8000u) << 16, e = (h >> 10) & 0x1fu, m = h & 0x3ffu, x;
    if (e == 0) {
        float v = (float)m / 16777216.0f; /* m * 2^-24 */
        return sign ? -v : v;
    }
    x = sign | (e == 31 ? 0x7f800000u | (m << 13) : ((e - 15 + 127) << 23) | (m << 13));
    float f;
    memcpy(&f, &x, sizeof f);
    return f;
}

/* n halves of src, and src rounded through them in place */
static uint16_t *halves(float *src, size_t n) {
    uint16_t *h = malloc(sizeof(uint16_t) * n);
    if (!h) exit(2);
    for (size_t i = 0; i < n; i++) {
        h[i] = to_half(src[i]);
        src[i] = from_half(h[i]);
    }
    return h;
}

static double now_ms(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec * 1e3 + (double)t.tv_nsec * 1e-6;
}

#define CHECK(call)                                                                   \
    do {                                                                              \
        LrdStatus s_ = (call);                                                        \
        if (s_ != LRD_STATUS_OK) {                                                    \
            fprintf(stderr, "%s:%d: %s -> %s\n", __FILE__, __LINE__, #call,           \
                    lrd_status_string(s_));                                           \
            exit(1);                                                                  \
        }                                                                             \
    } while (0)

typedef struct {
    const LrdFlrConfig *cfg;
    const LrdFrame *frame;
    const LrdImageMut *out;
    void *scratch;
    size_t bytes;
    uint32_t tiles;
    uint32_t worker;
    pthread_barrier_t *barrier;
    LrdReport report;
    LrdStatus status;
} Job;

static void *run_tiles(void *arg) {
    Job *j = (Job *)arg;
    /* BLEND only does work with the adaptive window; it is cheap to always run it. */
    const uint32_t stages[] = {LRD_STAGE_PREPARE, LRD_STAGE_MOMENTS, LRD_STAGE_STATS,
                               LRD_STAGE_BLUR_ROWS, LRD_STAGE_BLUR_COLS_SOLVE,
                               LRD_STAGE_BLEND, LRD_STAGE_APPLY};
    for (int s = 0; s < (int)(sizeof stages / sizeof stages[0]); s++) {
        uint32_t st = stages[s];
        uint32_t n = (st == LRD_STAGE_PREPARE || st == LRD_STAGE_STATS) ? 1 : j->tiles;
        for (uint32_t t = j->worker; t < n; t += WORKERS) {
            LrdStatus r = lrd_flr_run_tile(j->cfg, j->frame, j->out, j->scratch, j->bytes, WORKERS, st, t,
                                           j->worker, &j->report);
            if (r != LRD_STATUS_OK && j->status == LRD_STATUS_OK) j->status = r;
        }
        pthread_barrier_wait(j->barrier); /* every tile of a stage before the next stage */
    }
    return NULL;
}

/* A thread pool for the `..._parallel` entry points (LrdExecutor): for_each
   starts WORKERS threads that take the task indices from a shared counter;
   each passes its own worker index. An engine hands its job system here. */
typedef struct {
    LrdTask task;
    void *task_data;
    uint32_t count;
    uint32_t next; /* the next index, taken with an atomic add */
} PoolJob;

typedef struct {
    PoolJob *job;
    uint32_t worker;
} PoolThread;

static void *pool_thread(void *arg) {
    PoolThread *t = (PoolThread *)arg;
    for (;;) {
        uint32_t i = __atomic_fetch_add(&t->job->next, 1, __ATOMIC_RELAXED);
        if (i >= t->job->count) break;
        t->job->task(t->job->task_data, i, t->worker);
    }
    return NULL;
}

static void pool_for_each(void *pool, uint32_t count, LrdTask task, void *task_data) {
    (void)pool;
    PoolJob job = {task, task_data, count, 0};
    PoolThread threads[WORKERS];
    pthread_t th[WORKERS];
    for (uint32_t w = 0; w < WORKERS; w++) threads[w] = (PoolThread){&job, w};
    uint32_t started = 1;
    while (started < WORKERS && pthread_create(&th[started], NULL, pool_thread, &threads[started]) == 0) started++;
    pool_thread(&threads[0]); /* the calling thread takes what the others leave (all of it if none started) */
    for (uint32_t w = 1; w < started; w++) pthread_join(th[w], NULL);
}

int main(int argc, char **argv) {
    printf("lrdenoise %s, features 0x%x, simd %s\n", lrd_version(), lrd_features(), lrd_simd_level());
    float *noisy = malloc(sizeof(float) * 3 * W * H), *normal = malloc(sizeof(float) * 3 * W * H);
    float *depth = malloc(sizeof(float) * W * H), *ao = malloc(sizeof(float) * W * H);
    float *whole = malloc(sizeof(float) * 3 * W * H), *tiled = malloc(sizeof(float) * 3 * W * H);
    if (!noisy || !normal || !depth || !ao || !whole || !tiled) return 2;
    synthetic(noisy, normal, depth, ao);

    LrdFlrConfig cfg = lrd_flr_config_default(); /* normal + depth + ao */
    LrdFrame frame;
    memset(&frame, 0, sizeof frame); /* absent guides and guides_low: data == NULL */
    frame.noisy = image(noisy, 3);
    frame.guides.normal = image(normal, 3);
    frame.guides.depth = image(depth, 1);
    frame.guides.ao = image(ao, 1);
    LrdImageMut out;
    memset(&out, 0, sizeof out);
    out.data = whole;
    out.format = LRD_FORMAT_F32;
    out.width = W;
    out.height = H; /* strides 0: packed interleaved RGB */

    /* whole frame */
    size_t bytes = 0;
    CHECK(lrd_flr_scratch_size(&cfg, W, H, &bytes));
    void *scratch = malloc(bytes);
    if (!scratch) return 2;
    LrdReport rep;
    memset(&rep, 0, sizeof rep);
    CHECK(lrd_flr_denoise(&cfg, &frame, &out, scratch, bytes, &rep));
    double best = 1e30;
    for (int i = 0; i < 5; i++) {
        double t0 = now_ms();
        CHECK(lrd_flr_denoise(&cfg, &frame, &out, scratch, bytes, NULL));
        double dt = now_ms() - t0;
        if (dt < best) best = dt;
    }

    /* error paths */
    if (lrd_flr_denoise(&cfg, &frame, &out, scratch, bytes - 8, NULL) != LRD_STATUS_BUFFER_TOO_SMALL) return 3;
    if (lrd_flr_denoise(&cfg, NULL, &out, scratch, bytes, NULL) != LRD_STATUS_NULL_POINTER) return 3;
    if (lrd_flr_scratch_size(&cfg, W, H, NULL) != LRD_STATUS_NULL_POINTER) return 3;
    LrdFlrConfig bad = cfg;
    bad.block = 3;
    if (lrd_flr_scratch_size(&bad, W, H, &bytes) != LRD_STATUS_INVALID_CONFIG) return 3;
    LrdFrame missing = frame;
    missing.guides.ao.data = NULL;
    if (lrd_flr_denoise(&cfg, &missing, &out, scratch, bytes, NULL) != LRD_STATUS_GUIDE_MISMATCH) return 3;
    LrdFrame odd = frame;
    odd.noisy.pixel_stride = 5; /* not a multiple of sizeof(float) */
    if (lrd_flr_denoise(&cfg, &odd, &out, scratch, bytes, NULL) != LRD_STATUS_INVALID_ARGUMENT) return 3;
    if (lrd_status_string(9999) == NULL) return 3;

    /* sample weights: a checkerboard (half the pixels rendered, the clamp off); what the
       unrendered pixels hold changes no output value, and they still get one */
    {
        float *weights = malloc(sizeof(float) * W * H), *garbage = malloc(sizeof(float) * 3 * W * H);
        float *a = malloc(sizeof(float) * 3 * W * H), *b = malloc(sizeof(float) * 3 * W * H);
        if (!weights || !garbage || !a || !b) return 2;
        for (int i = 0; i < W * H; i++) {
            weights[i] = (float)((i % W + i / W) % 2);
            for (int c = 0; c < 3; c++) garbage[3 * i + c] = weights[i] != 0.0f ? noisy[3 * i + c] : 1e6f;
        }
        LrdFlrConfig plain = cfg;
        plain.fireflies = 0.0f;
        LrdFrame weighted = frame;
        weighted.sample_weights = image(weights, 1);
        LrdImageMut wout = out;
        wout.data = a;
        CHECK(lrd_flr_denoise(&plain, &weighted, &wout, scratch, bytes, NULL));
        weighted.noisy = image(garbage, 3);
        wout.data = b;
        CHECK(lrd_flr_denoise(&plain, &weighted, &wout, scratch, bytes, NULL));
        for (int i = 0; i < 3 * W * H; i++)
            if (a[i] != b[i] || !(a[i] == a[i])) return 4;
        /* weights that share memory with the output are refused */
        weighted.sample_weights = image(b, 1);
        if (lrd_flr_denoise(&plain, &weighted, &wout, scratch, bytes, NULL) != LRD_STATUS_INVALID_ARGUMENT) return 3;
        free(weights); free(garbage); free(a); free(b);
    }

    /* tiled on WORKERS threads (worker 0 on this one) */
    uint32_t tiles = 0;
    size_t tbytes = 0;
    CHECK(lrd_flr_tile_count(&cfg, W, H, &tiles));
    CHECK(lrd_flr_tiled_scratch_size(&cfg, W, H, WORKERS, &tbytes));
    void *tscratch = malloc(tbytes);
    if (!tscratch) return 2;
    LrdImageMut tout = out;
    tout.data = tiled;
    pthread_barrier_t barrier;
    pthread_barrier_init(&barrier, NULL, WORKERS);
    Job jobs[WORKERS];
    pthread_t th[WORKERS];
    for (uint32_t w = 0; w < WORKERS; w++) {
        memset(&jobs[w], 0, sizeof jobs[w]);
        jobs[w].cfg = &cfg;
        jobs[w].frame = &frame;
        jobs[w].out = &tout;
        jobs[w].scratch = tscratch;
        jobs[w].bytes = tbytes;
        jobs[w].tiles = tiles;
        jobs[w].worker = w;
        jobs[w].barrier = &barrier;
        jobs[w].status = LRD_STATUS_OK;
    }
    double t0 = now_ms();
    for (int w = 1; w < WORKERS; w++) {
        if (pthread_create(&th[w], NULL, run_tiles, &jobs[w]) != 0) {
            fprintf(stderr, "pthread_create failed\n"); /* the barrier needs every worker */
            return 2;
        }
    }
    run_tiles(&jobs[0]);
    for (int w = 1; w < WORKERS; w++) pthread_join(th[w], NULL);
    double tiled_ms = now_ms() - t0;
    pthread_barrier_destroy(&barrier);
    for (int w = 0; w < WORKERS; w++) {
        if (jobs[w].status != LRD_STATUS_OK) {
            fprintf(stderr, "tile worker %d: %s\n", w, lrd_status_string(jobs[w].status));
            return 1;
        }
    }
    if (memcmp(whole, tiled, sizeof(float) * 3 * W * H) != 0) {
        fprintf(stderr, "tiled output differs from whole-frame output\n");
        return 4;
    }
    printf("FLR %dx%d: whole frame %.3f ms (best of 5, 1 thread), tiled %u tiles on %d threads %.3f ms; identical\n",
           W, H, best, tiles, WORKERS, tiled_ms);

    /* Misuse is refused with a status, never answered with wrong output: the
       scratch records the frame's progress, and outputs may not overlap. */
    if (lrd_flr_run_tile(&cfg, &frame, &tout, tscratch, tbytes, WORKERS, LRD_STAGE_APPLY, 0, 0, NULL) != LRD_STATUS_STAGE_ORDER)
        return 3; /* the frame is done: APPLY again needs a new PREPARE */
    CHECK(lrd_flr_run_tile(&cfg, &frame, &tout, tscratch, tbytes, WORKERS, LRD_STAGE_PREPARE, 0, 0, NULL));
    if (lrd_flr_run_tile(&cfg, &frame, &tout, tscratch, tbytes, WORKERS, LRD_STAGE_APPLY, 0, 0, NULL) != LRD_STATUS_STAGE_ORDER)
        return 3; /* APPLY before its models exist */
    if (lrd_flr_run_tile(&cfg, &frame, &tout, tscratch, tbytes, WORKERS, LRD_STAGE_STATS, 0, 0, NULL) != LRD_STATUS_STAGE_ORDER)
        return 3; /* STATS before MOMENTS */
    LrdImageMut onto_noisy = out;
    onto_noisy.data = noisy;
    if (lrd_flr_denoise(&cfg, &frame, &onto_noisy, scratch, bytes, NULL) != LRD_STATUS_INVALID_ARGUMENT) return 3;
    LrdImageMut onto_scratch = out;
    onto_scratch.data = tscratch;
    if (lrd_flr_run_tile(&cfg, &frame, &onto_scratch, tscratch, tbytes, WORKERS, LRD_STAGE_PREPARE, 0, 0, NULL) !=
        LRD_STATUS_INVALID_ARGUMENT)
        return 3;
    LrdImageMut shared_pixels = out;
    shared_pixels.pixel_stride = sizeof(float); /* pixel x's green is pixel x+1's red */
    shared_pixels.channel_stride = sizeof(float);
    if (lrd_flr_denoise(&cfg, &frame, &shared_pixels, scratch, bytes, NULL) != LRD_STATUS_INVALID_ARGUMENT) return 3;
    printf("FLR misuse: out-of-order stages and overlapping outputs refused\n");

    /* Half-float buffers in and out (LRD_FORMAT_F16; the library converts them
     * with F16C where the CPU has it). Reading a half is exact, so the f16 run
     * must equal the f32 run on the same values, rounded to half on output. */
    {
        size_t n = (size_t)W * H;
        float *rn = malloc(sizeof(float) * 3 * n), *rnorm = malloc(sizeof(float) * 3 * n);
        float *rd = malloc(sizeof(float) * n), *ra = malloc(sizeof(float) * n);
        float *ref = malloc(sizeof(float) * 3 * n);
        uint16_t *hout = malloc(sizeof(uint16_t) * 3 * n);
        if (!rn || !rnorm || !rd || !ra || !ref || !hout) return 2;
        memcpy(rn, noisy, sizeof(float) * 3 * n);
        memcpy(rnorm, normal, sizeof(float) * 3 * n);
        memcpy(rd, depth, sizeof(float) * n);
        memcpy(ra, ao, sizeof(float) * n);
        uint16_t *hn = halves(rn, 3 * n), *hnorm = halves(rnorm, 3 * n), *hd = halves(rd, n), *ha = halves(ra, n);
        LrdFrame hf = frame;
        LrdImage *ims[4] = {&hf.noisy, &hf.guides.normal, &hf.guides.depth, &hf.guides.ao};
        const void *hdata[4] = {hn, hnorm, hd, ha};
        for (int k = 0; k < 4; k++) {
            ims[k]->data = hdata[k];
            ims[k]->format = LRD_FORMAT_F16;
            ims[k]->pixel_stride = (k < 2 ? 3 : 1) * sizeof(uint16_t);
        }
        LrdImageMut ho = out;
        ho.data = hout;
        ho.format = LRD_FORMAT_F16;
        CHECK(lrd_flr_denoise(&cfg, &hf, &ho, scratch, bytes, NULL));
        LrdFrame rf = frame;
        rf.noisy.data = rn;
        rf.guides.normal.data = rnorm;
        rf.guides.depth.data = rd;
        rf.guides.ao.data = ra;
        LrdImageMut ro = out;
        ro.data = ref;
        CHECK(lrd_flr_denoise(&cfg, &rf, &ro, scratch, bytes, NULL));
        for (size_t i = 0; i < 3 * n; i++) {
            if (hout[i] != to_half(ref[i])) {
                fprintf(stderr, "f16 output %zu: %#06x, f32 run rounded: %#06x (%g)\n", i, hout[i], to_half(ref[i]), ref[i]);
                return 6;
            }
        }
        printf("FLR f16 in and out: equal to the f32 run on the same values, rounded to half\n");
        free(rn); free(rnorm); free(rd); free(ra); free(ref); free(hout); free(hn); free(hnorm); free(hd); free(ha);
    }

    /* Temporal FLR: caller-owned scratch and history; a sub-pixel pan (motion
       = previous minus current position), so every pixel reprojects through
       four taps. */
    {
        LrdFlrConfig tcfg = lrd_flr_config_temporal_default(); /* smaller windows for accumulated light */
        LrdTemporalConfig tc = lrd_temporal_config_default();
        size_t sbytes = 0, hbytes = 0;
        CHECK(lrd_flr_temporal_sizes(&tcfg, &tc, W, H, &sbytes, &hbytes));
        void *tscratch = malloc(sbytes), *hdata = malloc(hbytes);
        float *tout = malloc(sizeof(float) * 3 * W * H), *mv = malloc(sizeof(float) * 2 * W * H);
        if (!tscratch || !hdata || !tout || !mv) return 2;
        for (size_t i = 0; i < (size_t)W * H; i++) {
            mv[2 * i] = 0.4f;
            mv[2 * i + 1] = -0.3f;
        }
        LrdImage motion = image(mv, 2);
        LrdHistory hist = {hdata, hbytes, 0};
        LrdImageMut to = out;
        to.data = tout;
        LrdReport trep;
        memset(&trep, 0, sizeof trep);
        for (int k = 0; k < 3; k++)
            CHECK(lrd_flr_denoise_temporal(&tcfg, &tc, &frame, k ? &motion : NULL, &hist, &to, tscratch, sbytes, &trep));
        for (size_t i = 0; i < 3 * (size_t)W * H; i++)
            if (!(tout[i] >= 0.0f && tout[i] < 1e30f)) return 6;
        if (hist.frames != 3) return 6;
        if (lrd_flr_denoise_temporal(&tcfg, NULL, &frame, &motion, &hist, &to, tscratch, sbytes, NULL) != LRD_STATUS_NULL_POINTER) return 3;
        printf("FLR temporal: 3 frames, %zu + %zu bytes of scratch + history, %llu pixels without history\n", sbytes, hbytes,
               (unsigned long long)trep.history_rejected);
        free(tscratch); free(hdata); free(tout); free(mv);
    }

    /* Temporal FLR on accumulated cell moments, on the calling thread and on
       the pool (LrdExecutor): the same bits. A pan of 5.5 px a frame. */
    {
        LrdFlrConfig mcfg = lrd_flr_config_temporal_moments_default();
        LrdTemporalConfig tc = lrd_temporal_config_default();
        LrdExecutor pool = {pool_for_each, NULL, WORKERS};
        size_t sb1 = 0, sbn = 0, hbytes = 0, hb2 = 0;
        CHECK(lrd_flr_temporal_moments_sizes(&mcfg, &tc, W, H, &sb1, &hbytes));
        CHECK(lrd_flr_temporal_moments_parallel_sizes(&mcfg, &tc, W, H, WORKERS, &sbn, &hb2));
        if (hb2 != hbytes) return 6; /* one history serves both calls */
        void *s1 = malloc(sb1), *sn = malloc(sbn), *h1 = malloc(hbytes), *hn = malloc(hbytes);
        float *o1 = malloc(sizeof(float) * 3 * W * H), *on = malloc(sizeof(float) * 3 * W * H);
        float *mv = malloc(sizeof(float) * 2 * W * H);
        if (!s1 || !sn || !h1 || !hn || !o1 || !on || !mv) return 2;
        for (size_t i = 0; i < (size_t)W * H; i++) {
            mv[2 * i] = 5.5f;
            mv[2 * i + 1] = 0.0f;
        }
        LrdImage motion = image(mv, 2);
        LrdHistory hist1 = {h1, hbytes, 0}, histn = {hn, hbytes, 0};
        LrdImageMut out1 = out, outn = out;
        out1.data = o1;
        outn.data = on;
        LrdReport mrep;
        memset(&mrep, 0, sizeof mrep);
        for (int k = 0; k < 3; k++) {
            const LrdImage *m = k ? &motion : NULL;
            CHECK(lrd_flr_denoise_temporal_moments(&mcfg, &tc, &frame, m, &hist1, &out1, s1, sb1, &mrep));
            CHECK(lrd_flr_denoise_temporal_moments_parallel(&mcfg, &tc, &frame, m, &histn, &outn, sn, sbn, &pool, NULL));
            if (memcmp(o1, on, sizeof(float) * 3 * W * H) != 0) {
                fprintf(stderr, "moments frame %d: the pool's output differs from the calling thread's\n", k);
                return 6;
            }
        }
        if (histn.frames != 3) return 6;
        if (lrd_flr_denoise_temporal_moments_parallel(&mcfg, &tc, &frame, &motion, &histn, &outn, sn, sbn, NULL, NULL) !=
            LRD_STATUS_NULL_POINTER)
            return 3;
        printf("FLR temporal moments: 3 frames on %d threads equal to the calling thread's, %zu + %zu bytes of scratch + "
               "history, %llu cells without history\n",
               WORKERS, sbn, hbytes, (unsigned long long)mrep.history_rejected);
        free(s1); free(sn); free(h1); free(hn); free(o1); free(on); free(mv);
    }

    /* BMFR's temporal pipeline: caller-owned scratch and history, static camera
       (motion NULL); the client's frame has normals and depth, no positions. */
    {
        LrdBmfrConfig bcfg = lrd_bmfr_config_default();
        bcfg.guides = LRD_GUIDE_NORMAL | LRD_GUIDE_DEPTH; /* features 1, n, d, d^2 */
        LrdFrame bframe = frame;
        memset(&bframe.guides.ao, 0, sizeof bframe.guides.ao);
        size_t sbytes = 0, hbytes = 0;
        CHECK(lrd_bmfr_temporal_sizes(&bcfg, W, H, &sbytes, &hbytes));
        void *bscratch = malloc(sbytes), *hdata = malloc(hbytes);
        float *bout = malloc(sizeof(float) * 3 * W * H);
        if (!bscratch || !hdata || !bout) return 2;
        LrdHistory hist = {hdata, hbytes, 0};
        LrdImageMut bo = out;
        bo.data = bout;
        LrdReport brep;
        memset(&brep, 0, sizeof brep);
        for (int k = 0; k < 3; k++)
            CHECK(lrd_bmfr_denoise_temporal(&bcfg, &bframe, NULL, &hist, &bo, bscratch, sbytes, &brep));
        for (size_t i = 0; i < 3 * (size_t)W * H; i++)
            if (!(bout[i] >= 0.0f && bout[i] < 1e30f)) return 6;
        if (hist.frames != 3) return 6;
        if (lrd_bmfr_denoise_temporal(&bcfg, &frame, NULL, &hist, &bo, bscratch, sbytes, NULL) != LRD_STATUS_GUIDE_MISMATCH) return 3;
        printf("BMFR temporal: 3 frames, %zu + %zu bytes of scratch + history, %llu features dropped\n", sbytes, hbytes,
               (unsigned long long)brep.dropped_pivots);
        free(bscratch); free(hdata); free(bout);
    }

    /* FLNR: the network's weights are the caller's bytes (train/flnr.bin, path in
       argv[2]). On the frame's top-left FW x FH pixels (views with the frame's
       row stride: no copy; small, as this runs under valgrind in CI): whole
       frame, then the threaded stages in order on this thread (PREPARE, every
       NETWORK tile on worker t % 2, FLR), which must give the same output. */
    if (argc > 2) {
        enum { FW = 72, FH = 40 };
        FILE *wf = fopen(argv[2], "rb");
        if (!wf) return 7;
        if (fseek(wf, 0, SEEK_END) != 0) return 7;
        long wlen = ftell(wf);
        if (wlen <= 0 || fseek(wf, 0, SEEK_SET) != 0) return 7;
        uint8_t *wts = malloc((size_t)wlen);
        if (!wts || fread(wts, 1, (size_t)wlen, wf) != (size_t)wlen) return 7;
        fclose(wf);
        LrdFrame crop = frame;
        LrdImage *views[] = {&crop.noisy, &crop.guides.normal, &crop.guides.depth, &crop.guides.ao};
        for (size_t v = 0; v < sizeof views / sizeof views[0]; v++) {
            views[v]->row_stride = (size_t)W * views[v]->pixel_stride;
            views[v]->width = FW;
            views[v]->height = FH;
        }
        LrdFlnrConfig fcfg = lrd_flnr_config_default(wts, (size_t)wlen);
        fcfg.tile = 64; /* 2 x 1 tiles here; 0 = the default (512) */
        size_t fbytes = 0, tbytes = 0;
        uint32_t ftiles = 0;
        CHECK(lrd_flnr_scratch_size(&fcfg, FW, FH, &fbytes));
        CHECK(lrd_flnr_tile_count(&fcfg, FW, FH, &ftiles));
        CHECK(lrd_flnr_tiled_scratch_size(&fcfg, FW, FH, 2, &tbytes));
        void *fscratch = malloc(fbytes), *ftscratch = malloc(tbytes);
        float *fa = malloc(sizeof(float) * 3 * FW * FH), *fb = malloc(sizeof(float) * 3 * FW * FH);
        if (!fscratch || !ftscratch || !fa || !fb) return 2;
        LrdImageMut fo = out;
        fo.width = FW;
        fo.height = FH;
        fo.data = fa;
        double t0 = now_ms();
        CHECK(lrd_flnr_denoise(&fcfg, &crop, &fo, fscratch, fbytes, NULL));
        double flnr_ms = now_ms() - t0;
        fo.data = fb;
        CHECK(lrd_flnr_run_tile(&fcfg, &crop, &fo, ftscratch, tbytes, 2, LRD_FLNR_STAGE_PREPARE, 0, 0, NULL));
        for (uint32_t t = 0; t < ftiles; t++)
            CHECK(lrd_flnr_run_tile(&fcfg, &crop, &fo, ftscratch, tbytes, 2, LRD_FLNR_STAGE_NETWORK, t, t % 2, NULL));
        CHECK(lrd_flnr_run_tile(&fcfg, &crop, &fo, ftscratch, tbytes, 2, LRD_FLNR_STAGE_FLR, 0, 0, NULL));
        if (memcmp(fa, fb, sizeof(float) * 3 * FW * FH) != 0) return 8;
        for (size_t i = 0; i < 3 * (size_t)FW * FH; i++)
            if (!(fa[i] >= 0.0f && fa[i] < 1e30f)) return 8;
        LrdFlnrConfig fbad = fcfg;
        fbad.weights_bytes -= 1;
        if (lrd_flnr_denoise(&fbad, &crop, &fo, fscratch, fbytes, NULL) != LRD_STATUS_INVALID_CONFIG) return 3;
        printf("FLNR %dx%d crop: %zu bytes of weights, %zu bytes of scratch, whole %.1f ms; %u tiles in stages: identical\n",
               FW, FH, (size_t)wlen, fbytes, flnr_ms, ftiles);
        free(wts); free(fscratch); free(ftscratch); free(fa); free(fb);
    }

    /* The GPU path: what an engine needs to run the compute shaders itself. */
    LrdGpuDispatch gpu;
    CHECK(lrd_gpu_dispatch(&cfg, W, H, LRD_FORMAT_F32, &gpu));
    printf("GPU: %zu bytes of WGSL; passes:", strlen(lrd_gpu_wgsl()));
    for (uint32_t i = 0; i < gpu.pass_count; i++)
        printf(" %s %ux%u", gpu.passes[i].entry, gpu.passes[i].workgroups[0], gpu.passes[i].workgroups[1]);
    printf("; output buffer %llu bytes\n", (unsigned long long)gpu.buffer_bytes[7]);

    /* Temporal FLR on the GPU: the stage's passes around FLR's, the history on the device. */
    LrdTemporalConfig tgc = lrd_temporal_config_default();
    LrdGpuTemporalDispatch tgpu;
    CHECK(lrd_gpu_temporal_dispatch(&cfg, &tgc, W, H, &tgpu));
    printf("GPU temporal: %zu bytes of WGSL; %s .. %s, FLR's %u passes, %s; two history slots of %llu bytes\n",
           strlen(lrd_gpu_temporal_wgsl()), tgpu.before[0].entry, tgpu.before[3].entry, tgpu.flr.pass_count,
           tgpu.after.entry, (unsigned long long)tgpu.buffer_bytes[3]);
    {
        size_t tsb = 0, thb = 0;
        CHECK(lrd_flr_temporal_sizes(&cfg, &tgc, W, H, &tsb, &thb));
        if (2 * tgpu.buffer_bytes[3] != thb) return 9; /* the slots are the CPU history */
        /* history judged by world positions too: they go into the work buffer after the motion */
        tgc.rejection_guides = LRD_GUIDE_NORMAL | LRD_GUIDE_DEPTH | LRD_GUIDE_POSITION;
        CHECK(lrd_gpu_temporal_dispatch(&cfg, &tgc, W, H, &tgpu));
        CHECK(lrd_flr_temporal_sizes(&cfg, &tgc, W, H, &tsb, &thb));
        if (2 * tgpu.buffer_bytes[3] != thb || tgpu.work_guides[1] == UINT64_MAX) return 9;
        printf("GPU temporal with positions: upload them at byte %llu of the work buffer\n",
               (unsigned long long)tgpu.work_guides[1]);
    }

    if (argc > 1) {
        FILE *f = fopen(argv[1], "wb");
        if (!f || fwrite(whole, sizeof(float), 3 * W * H, f) != 3 * W * H) return 5;
        fclose(f);
    }
    free(noisy); free(normal); free(depth); free(ao); free(whole); free(tiled); free(scratch); free(tscratch);
    return 0;
}
