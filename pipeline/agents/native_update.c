/* One DQN update of the Dueling Q-network in one call, for the CPU (agent.update_backend: native).
 *
 * The same update as DQNLearner.update in dqn.py: online network on s and s', target network on
 * s', Double-DQN target, mean squared (or Huber) TD error, hand-written backward pass, global
 * gradient-norm clipping, Adam/AdamW (optionally AMSGrad), Polyak averaging. Python loads this
 * file through pipeline/agents/native.py, which compiles it on first use.
 *
 * Why it exists: at batch 64 PyTorch spends most of an update between its few dozen small
 * operations (dispatch, and on two threads a fork and join of the thread team per operation;
 * README "Speed"). Here the work is cut coarsely into PARTS parts: every layer's output columns
 * in the forward pass, the batch rows in the loss and the input gradients, the output rows of
 * every weight gradient, the flat buffer in the norm and the optimiser step, and the value and
 * advantage streams. Each thread takes whole parts, and the threads meet at a barrier between
 * phases. The matrix products are MKL's sgemm (the one inside PyTorch), single-threaded in each
 * thread. Since the parts do not depend on the number of threads, neither do the results: one
 * thread computes every part in turn and gets the same numbers, bit for bit.
 *
 * Layout (all row-major float32): a Linear layer's weight is (out, in) followed by its bias
 * (out), at the offsets given in `lay` into the flat parameter buffers (the order of
 * DuelingQNetwork.parameters()). The rounding differs from PyTorch's (other product shapes, other
 * summation orders), so trainings with the two backends differ after the first update.
 */
#include <math.h>
#include <omp.h>
#include <string.h>

/* mkl_service.h maps mkl_set_num_threads_local to this name (the lowercase symbol is Fortran's) */
extern int MKL_Set_Num_Threads_Local(int nthreads);
extern void sgemm_(const char *transa, const char *transb, const int *m, const int *n,
                   const int *k, const float *alpha, const float *a, const int *lda,
                   const float *b, const int *ldb, const float *beta, float *c, const int *ldc);

#define SLOPE 0.01f  /* LeakyReLU negative slope (dueling.py LEAKY_SLOPE) */
#define PARTS 2      /* parts of every phase; at most PARTS threads are used */
#define MAX_LAYERS 64 /* trunk layers (native.py MAX_TRUNK_LAYERS) */

/* Row-major C (m x n) = op(A) (m x k) . op(B) (k x n) + beta C; ta/tb: use the transpose of A/B
 * as stored. Column-major sgemm computes C^T = op(B)^T op(A)^T. */
static void gemm(int ta, int tb, int m, int n, int k, const float *a, int lda, const float *b,
                 int ldb, float beta, float *c, int ldc) {
    const float one = 1.0f;
    if (m <= 0 || n <= 0) return;
    sgemm_(tb ? "T" : "N", ta ? "T" : "N", &n, &m, &k, &one, b, &ldb, a, &lda, &beta, c, &ldc);
}

static inline float leaky(float x) { return x > 0.0f ? x : x * SLOPE; }

/* Part k of PARTS of 0..n: [*lo, *hi), in multiples of `align` but the last. */
static void part(long n, int k, long align, long *lo, long *hi) {
    long per = (n + PARTS - 1) / PARTS;
    per = (per + align - 1) / align * align;
    *lo = per * k < n ? per * k : n;
    *hi = per * (k + 1) < n ? per * (k + 1) : n;
}

/* lay: [L, S, A, W_0, b_0, in_0, out_0, ..., W_{L-1}, b_{L-1}, in_{L-1}, out_{L-1},
 *       value W1, b1, W2, b2, advantage W1, b1, W2, b2]   (offsets in floats) */
#define TRUNK(l, i) lay[3 + 4 * (l) + (i)]

static long max_width(const long *lay) {
    long w = lay[1], L = lay[0];
    for (long l = 0; l < L; l++) {
        if (TRUNK(l, 2) > w) w = TRUNK(l, 2);
        if (TRUNK(l, 3) > w) w = TRUNK(l, 3);
    }
    return w;
}

/* Floats of workspace an update of `batch` rows needs. */
long native_workspace(const long *lay, int batch) {
    long L = lay[0], S = lay[1], A = lay[2], B = batch, widths = 0;
    for (long l = 0; l < L; l++) widths += TRUNK(l, 3);
    long forward = 3 * B * (2 * widths + 4 * S + 1 + A); /* online 2B rows, target B rows */
    long backward = B * (1 + A + 2 * S) + B * widths + B * max_width(lay);
    return 2 * B * TRUNK(0, 2) + forward + backward + 64;
}

/* One update with nt threads (at most PARTS are used). w, tw, g: online weights, target weights,
 * gradients (flat, P floats); m1, m2, vmax: Adam's moments (vmax: AMSGrad's maximum, read only
 * with flags[1]); ws: native_workspace() floats; the batch: s, s2 (batch x in), actions (int64),
 * rewards, terminals, discounts; hyper: lr, beta1, beta2, eps, polyak, clip, weight decay, the
 * two bias corrections; flags: huber, amsgrad, adamw; partials: 2 * PARTS doubles of scratch.
 * Returns the mean loss; writes the gradient norm (before clipping) to *norm_out. */
double native_update(int nt, const long *lay, int batch, float *w, float *tw, float *g, float *m1,
                     float *m2, float *vmax, float *ws, const float *s, const float *s2,
                     const long *actions, const float *rewards, const float *terminals,
                     const float *discounts, const float *hyper, const int *flags,
                     double *partials, long P, float *norm_out) {
    const long L = lay[0], S = lay[1], A = lay[2], B = batch, B2 = 2 * batch;
    const long D = TRUNK(0, 2), WL = TRUNK(L - 1, 3), MW = max_width(lay);
    const long *vlay = lay + 3 + 4 * L, *alay = vlay + 4;
    const float lr = hyper[0], beta1 = hyper[1], beta2 = hyper[2], eps = hyper[3];
    const float polyak = hyper[4], clip = hyper[5], wd = hyper[6];
    const float bc1 = hyper[7], bc2 = hyper[8];
    const int huber = flags[0], amsgrad = flags[1], adamw = flags[2];

    /* Workspace: X = [s; s'] then, per trunk layer, online (2B rows) and target (B rows)
     * pre-activations and activations; the streams likewise; then the backward buffers. */
    float *p = ws;
    float *X = p;
    p += B2 * D;
    float *pre[MAX_LAYERS], *act[MAX_LAYERS], *tpre[MAX_LAYERS], *tact[MAX_LAYERS];
    float *dpre[MAX_LAYERS];
    for (long l = 0; l < L; l++) {
        long o = TRUNK(l, 3);
        pre[l] = p, p += B2 * o, act[l] = p, p += B2 * o;
        tpre[l] = p, p += B * o, tact[l] = p, p += B * o;
    }
    float *spre[2], *sact[2], *tspre[2], *tsact[2], *out[2], *tout[2];
    for (int k = 0; k < 2; k++) {
        spre[k] = p, p += B2 * S, sact[k] = p, p += B2 * S;
        tspre[k] = p, p += B * S, tsact[k] = p, p += B * S;
    }
    out[0] = p, p += B2, out[1] = p, p += B2 * A;
    tout[0] = p, p += B, tout[1] = p, p += B * A;
    float *dv = p; /* d(loss)/d(value output), B */
    p += B;
    float *da = p; /* d(loss)/d(advantage outputs), B x A */
    p += B * A;
    float *dsp[2];
    dsp[0] = p, p += B * S, dsp[1] = p, p += B * S;
    for (long l = 0; l < L; l++) dpre[l] = p, p += B * TRUNK(l, 3);
    float *scratch = p;
    double *loss_part = partials, *norm_part = partials + PARTS;
    if (nt > PARTS) nt = PARTS;
    if (nt < 1) nt = 1;

    memcpy(X, s, sizeof(float) * B * D);
    memcpy(X + B * D, s2, sizeof(float) * B * D);

#pragma omp parallel num_threads(nt)
    {
        const int t = omp_get_thread_num();
        const int mkl_threads = MKL_Set_Num_Threads_Local(1);
        long lo, hi;
        /* -- forward: part k of every trunk layer's output columns, all rows ---------------- */
        for (long l = 0; l < L; l++) {
            const long in = TRUNK(l, 2), o = TRUNK(l, 3);
            const float *W = w + TRUNK(l, 0), *b = w + TRUNK(l, 1);
            const float *tW = tw + TRUNK(l, 0), *tb = tw + TRUNK(l, 1);
            const float *x = l ? act[l - 1] : X, *tx = l ? tact[l - 1] : X + B * D;
            for (int k = t; k < PARTS; k += nt) {
                part(o, k, 16, &lo, &hi);
                const size_t bytes = sizeof(float) * (hi - lo);
                for (long r = 0; r < B2; r++) memcpy(pre[l] + r * o + lo, b + lo, bytes);
                for (long r = 0; r < B; r++) memcpy(tpre[l] + r * o + lo, tb + lo, bytes);
                gemm(0, 1, B2, hi - lo, in, x, in, W + lo * in, in, 1.0f, pre[l] + lo, o);
                gemm(0, 1, B, hi - lo, in, tx, in, tW + lo * in, in, 1.0f, tpre[l] + lo, o);
                for (long r = 0; r < B2; r++)
                    for (long c = lo; c < hi; c++) act[l][r * o + c] = leaky(pre[l][r * o + c]);
                for (long r = 0; r < B; r++)
                    for (long c = lo; c < hi; c++) tact[l][r * o + c] = leaky(tpre[l][r * o + c]);
            }
#pragma omp barrier
        }
        /* -- the value (k = 0) and advantage (k = 1) streams -------------------------------- */
        for (int k = t; k < 2; k += nt) {
            const long *sl = k ? alay : vlay;
            const long no = k ? A : 1;
            const float *h = act[L - 1], *th = tact[L - 1];
            for (long r = 0; r < B2; r++) memcpy(spre[k] + r * S, w + sl[1], sizeof(float) * S);
            for (long r = 0; r < B; r++) memcpy(tspre[k] + r * S, tw + sl[1], sizeof(float) * S);
            gemm(0, 1, B2, S, WL, h, WL, w + sl[0], WL, 1.0f, spre[k], S);
            gemm(0, 1, B, S, WL, th, WL, tw + sl[0], WL, 1.0f, tspre[k], S);
            for (long i = 0; i < B2 * S; i++) sact[k][i] = leaky(spre[k][i]);
            for (long i = 0; i < B * S; i++) tsact[k][i] = leaky(tspre[k][i]);
            for (long r = 0; r < B2; r++) memcpy(out[k] + r * no, w + sl[3], sizeof(float) * no);
            for (long r = 0; r < B; r++) memcpy(tout[k] + r * no, tw + sl[3], sizeof(float) * no);
            gemm(0, 1, B2, no, S, sact[k], S, w + sl[2], S, 1.0f, out[k], no);
            gemm(0, 1, B, no, S, tsact[k], S, tw + sl[2], S, 1.0f, tout[k], no);
        }
#pragma omp barrier
        /* -- loss and input gradients: part k of the batch rows ----------------------------- */
        for (int k = t; k < PARTS; k += nt) {
            part(B, k, 1, &lo, &hi);
            double loss = 0.0;
            for (long i = lo; i < hi; i++) {
                /* Q = V + A - mean(A) for s (online), s' (online) and s' (target) */
                float mean = 0.0f, mean_next = 0.0f, mean_target = 0.0f;
                for (long j = 0; j < A; j++) {
                    mean += out[1][i * A + j];
                    mean_next += out[1][(B + i) * A + j];
                    mean_target += tout[1][i * A + j];
                }
                mean /= (float)A, mean_next /= (float)A, mean_target /= (float)A;
                long best = 0; /* Double DQN: the online network picks, the target values */
                float best_q = out[0][B + i] + out[1][(B + i) * A] - mean_next;
                for (long j = 1; j < A; j++) {
                    float q = out[0][B + i] + out[1][(B + i) * A + j] - mean_next;
                    if (q > best_q) best = j, best_q = q;
                }
                const float next_value = tout[0][i] + tout[1][i * A + best] - mean_target;
                const float y = rewards[i] + discounts[i] * next_value * (1.0f - terminals[i]);
                const long a = actions[i];
                const float e = out[0][i] + out[1][i * A + a] - mean - y;
                float ge; /* d(loss)/d(error) */
                if (huber) {
                    const float ae = fabsf(e);
                    loss += ae < 1.0f ? 0.5 * e * e : ae - 0.5;
                    ge = (e > 1.0f ? 1.0f : (e < -1.0f ? -1.0f : e)) / (float)B;
                } else {
                    loss += (double)e * e;
                    ge = e * (2.0f / (float)B);
                }
                /* dQ is ge at the action taken: dV = sum_a dQ, dA = dQ - mean_a dQ */
                dv[i] = ge;
                for (long j = 0; j < A; j++) da[i * A + j] = (j == a ? ge : 0.0f) - ge / (float)A;
                const float *v2 = w + vlay[2], *a2 = w + alay[2];
                for (long c = 0; c < S; c++) {
                    float gv = ge * v2[c], ga = 0.0f;
                    for (long j = 0; j < A; j++) ga += da[i * A + j] * a2[j * S + c];
                    dsp[0][i * S + c] = spre[0][i * S + c] > 0.0f ? gv : gv * SLOPE;
                    dsp[1][i * S + c] = spre[1][i * S + c] > 0.0f ? ga : ga * SLOPE;
                }
            }
            loss_part[k] = loss;
            /* these rows' d(loss)/d(trunk output), then down the trunk */
            const long rows = hi - lo;
            float *dh = scratch + lo * MW;
            gemm(0, 0, rows, WL, S, dsp[0] + lo * S, S, w + vlay[0], WL, 0.0f, dh, WL);
            gemm(0, 0, rows, WL, S, dsp[1] + lo * S, S, w + alay[0], WL, 1.0f, dh, WL);
            for (long l = L - 1; l >= 0; l--) {
                const long in = TRUNK(l, 2), o = TRUNK(l, 3);
                for (long r = 0; r < rows; r++)
                    for (long c = 0; c < o; c++) {
                        const float d = dh[r * o + c];
                        dpre[l][(lo + r) * o + c] = pre[l][(lo + r) * o + c] > 0.0f ? d : d * SLOPE;
                    }
                if (l > 0)
                    gemm(0, 0, rows, in, o, dpre[l] + lo * o, o, w + TRUNK(l, 0), in, 0.0f, dh, in);
            }
        }
#pragma omp barrier
        /* -- weight gradients: part k of every trunk layer's output rows; the streams -------- */
        for (int k = t; k < PARTS; k += nt)
            for (long l = 0; l < L; l++) {
                const long in = TRUNK(l, 2), o = TRUNK(l, 3);
                const float *x = l ? act[l - 1] : X; /* the first B rows: s */
                float *gW = g + TRUNK(l, 0), *gb = g + TRUNK(l, 1);
                part(o, k, 16, &lo, &hi);
                gemm(1, 0, hi - lo, in, B, dpre[l] + lo, o, x, in, 0.0f, gW + lo * in, in);
                for (long c = lo; c < hi; c++) gb[c] = 0.0f;
                for (long r = 0; r < B; r++)
                    for (long c = lo; c < hi; c++) gb[c] += dpre[l][r * o + c];
            }
        for (int k = t; k < 2; k += nt) {
            const long *sl = k ? alay : vlay;
            const long no = k ? A : 1;
            const float *dout = k ? da : dv;
            float *gb1 = g + sl[1], *gb2 = g + sl[3];
            gemm(1, 0, S, WL, B, dsp[k], S, act[L - 1], WL, 0.0f, g + sl[0], WL);
            gemm(1, 0, no, S, B, dout, no, sact[k], S, 0.0f, g + sl[2], S);
            for (long c = 0; c < S; c++) gb1[c] = 0.0f;
            for (long c = 0; c < no; c++) gb2[c] = 0.0f;
            for (long r = 0; r < B; r++) {
                for (long c = 0; c < S; c++) gb1[c] += dsp[k][r * S + c];
                for (long c = 0; c < no; c++) gb2[c] += dout[r * no + c];
            }
        }
#pragma omp barrier
        /* -- global gradient norm, clipping, Adam, Polyak: part k of the flat buffer --------- */
        for (int k = t; k < PARTS; k += nt) {
            part(P, k, 16, &lo, &hi);
            float sq = 0.0f;
#pragma omp simd reduction(+ : sq)
            for (long i = lo; i < hi; i++) sq += g[i] * g[i];
            norm_part[k] = sq;
        }
#pragma omp barrier
        double total = 0.0;
        for (int k = 0; k < PARTS; k++) total += norm_part[k];
        const float norm = (float)sqrt(total);
        float scale = 1.0f; /* clip_grad_norm_: min(1, clip / (norm + 1e-6)) */
        if (clip > 0.0f && clip / (norm + 1e-6f) < 1.0f) scale = clip / (norm + 1e-6f);
        if (t == 0) *norm_out = norm;
        const float step_size = lr / bc1, bc2_sqrt = sqrtf(bc2), keep = 1.0f - polyak;
        /* AdamW decays the weights; Adam adds the L2 term to the gradient */
        const float decay = adamw ? 1.0f - lr * wd : 1.0f, l2 = adamw ? 0.0f : wd;
        for (int k = t; k < PARTS; k += nt) {
            part(P, k, 16, &lo, &hi);
            if (scale != 1.0f) /* the clipped gradient stays in g, as clip_grad_norm_ leaves it */
                for (long i = lo; i < hi; i++) g[i] *= scale;
            if (amsgrad) {
#pragma omp simd
                for (long i = lo; i < hi; i++) {
                    float gi = g[i], wi = w[i] * decay;
                    gi += l2 * wi;
                    const float m = beta1 * m1[i] + (1.0f - beta1) * gi;
                    float v = beta2 * m2[i] + (1.0f - beta2) * gi * gi;
                    m1[i] = m, m2[i] = v;
                    v = v > vmax[i] ? v : vmax[i];
                    vmax[i] = v;
                    wi -= step_size * m / (sqrtf(v) / bc2_sqrt + eps);
                    w[i] = wi;
                    tw[i] += keep * (wi - tw[i]);
                }
            } else {
#pragma omp simd
                for (long i = lo; i < hi; i++) {
                    float gi = g[i], wi = w[i] * decay;
                    gi += l2 * wi;
                    const float m = beta1 * m1[i] + (1.0f - beta1) * gi;
                    const float v = beta2 * m2[i] + (1.0f - beta2) * gi * gi;
                    m1[i] = m, m2[i] = v;
                    wi -= step_size * m / (sqrtf(v) / bc2_sqrt + eps);
                    w[i] = wi;
                    tw[i] += keep * (wi - tw[i]);
                }
            }
        }
        MKL_Set_Num_Threads_Local(mkl_threads);
    }
    double loss = 0.0;
    for (int k = 0; k < PARTS; k++) loss += loss_part[k];
    return loss / (double)B;
}
