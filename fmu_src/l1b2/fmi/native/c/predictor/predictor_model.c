/*
 * predictor_model.c - the Eq. 29 speed predictor of the native Predictor FMU.
 *
 * The operations of l1b2.predictor.model (force_parts, rest_sign, step_drive,
 * one_step, steady_state) and of l1b2.cosim.composite.PredictorBlock
 * (initialize, do_step: Eq. 29 iterated at sub-steps of at most T_s), in the same
 * order; the Legendre series are summed term by term (numpy's legvander and a dot
 * product). tests/test_native_fmu.py compares the outputs with the Python FMU's.
 */
#include <math.h>
#include <stdio.h>

#include "fmu_core.h"
#if PRED_EXTENDED
#include "effect_kernels.h"
#endif

#define G_M_S2 9.81
#define PI 3.141592653589793

static void position_terms(const PredictorParams* q, double s, double* Ap, double* Bp, double* P)
{
    double x = (s - q->s_center) / q->s_half;
    double v[PRED_NP];
    v[0] = 1.0; /* x * 0 + 1 */
    if (PRED_NP > 1) v[1] = x;
    for (int i = 2; i < PRED_NP; i++) v[i] = (v[i - 1] * x * (2 * i - 1) - v[i - 2] * (i - 1)) / i;
    double a = 0.0, b = 0.0, p = 0.0;
    for (int i = 0; i < PRED_NP; i++) {
        a += v[i] * q->alpha[i];
        b += v[i] * q->beta[i];
        p += v[i] * q->p[i];
    }
    *Ap = a;
    *Bp = b;
    *P = p;
}

/* D, X, Fr of force_parts (drive coordinates) */
static void force_parts(const PredictorParams* q, double s, double V0, double m_load_p, double m_s, double* D,
                        double* X, double* Fr)
{
    double Ap, Bp, P;
    position_terms(q, s, &Ap, &Bp, &P);
    double k0 = q->k0;
    double g1 = 2.0 * sqrt(1.0 - k0 * k0) - 1.0;
    double G = 2.0 * k0 * sqrt(1.0 - k0 * k0) - 2.0 * asin(k0) + 0.5 * PI;
    *D = q->c_r + q->sigma * (0.5 - Ap);
    *X = Bp * V0 + q->mu * P * (g1 - 0.5 * PI * Ap * G) - G_M_S2 * m_load_p;
    *Fr = q->mu_sd * (G_M_S2 * m_s + q->kappa * P);
}

static double sign(double x) { return x > 0 ? 1.0 : (x < 0 ? -1.0 : x); }

static double rest_sign(double X, double Fr)
{
    if (Fr > 0) {
        double z = X / Fr;
        z = z < -1.0 ? -1.0 : (z > 1.0 ? 1.0 : z);
        return -z;
    }
    return -sign(X);
}

static double step_drive(double vp, double D, double X, double Fr, double h)
{
    double z0 = rest_sign(X, Fr);
    double sg = sign(-vp);
    int rest = vp == 0;
    int stuck = fabs(z0) < 1.0;
    if (rest) sg = z0;
    double nw = vp + h * (-D * vp + X + sg * Fr);
    if (rest && stuck) nw = 0.0;
    if (vp * nw < 0) {
        double frac = vp / (vp - nw);
        double from_rest = stuck ? 0.0 : h * (X + z0 * Fr);
        nw = (1.0 - frac) * from_rest;
    }
    return nw;
}

/* has_F: the extra force F is added to X (l1b2.predictor.model.add_extra_force; without one X stays as it is) */
static double one_step(const PredictorParams* q, double v, double s, double V0, double load, double d, double dt,
                       int has_F, double F)
{
    double vp = d * v;
    double D, X, Fr;
    force_parts(q, s, V0, d * load, q->m_s, &D, &X, &Fr);
    if (has_F) X = X + F;
    double m_eff = q->load_inertia >= 0.5 ? q->m_s + fabs(load) : q->m_s + 0.0 * load;
    double h = dt / m_eff;
    return d * step_drive(vp, D, X, Fr, h);
}

static double steady_state(const PredictorParams* q, double s, double V0, double load, double d, int has_F,
                           double F)
{
    double D, X, Fr;
    force_parts(q, s, V0, d * load, q->m_s, &D, &X, &Fr);
    if (has_F) X = X + F;
    double fwd = X - Fr, bwd = X + Fr;
    double vp = fwd > 0 ? fwd / D : (bwd < 0 ? bwd / D : 0.0);
    if (!(D > 0)) vp = NAN;
    return d * vp;
}

static void outputs(Instance* c)
{
    double* r = c->s.r;
    r[VR_v] = r[VR_v_state];
#if PRED_EXTENDED
#if PRED_HAS_RAIL_LO
    r[VR_v] = fmax(r[VR_v], r[VR_speed_rail_lo]); /* the speed channel's range, its last stage */
#endif
#if PRED_HAS_RAIL_HI
    r[VR_v] = fmin(r[VR_v], r[VR_speed_rail_hi]);
#endif
    r[VR_v_steady] = steady_state(&c->s.ms.par, r[VR_s], r[VR_V0], r[VR_load], r[VR_direction], 1, r[VR_F_extra]);
    r[VR_v_baseline] = r[VR_v_base];
#else
    r[VR_v_steady] = steady_state(&c->s.ms.par, r[VR_s], r[VR_V0], r[VR_load], r[VR_direction], 0, 0.0);
#endif
}

/* one Eq. 29 setup from the variables (value references vs: PREDICTOR_SCALARS of l1b2.fmi.native.build),
 * checked as PredictorParams and PredictorBlock check them */
static int read_setup(const double* r, const int* vs, const int* va, const int* vb, const int* vp, const char* prefix,
                      PredictorParams* q, char* msg)
{
    q->c_r = r[vs[0]];
    q->sigma = r[vs[1]];
    q->mu = r[vs[2]];
    q->k0 = r[vs[3]];
    q->mu_sd = r[vs[4]];
    for (int i = 0; i < PRED_NP; i++) {
        q->alpha[i] = r[va[i]];
        q->beta[i] = r[vb[i]];
        q->p[i] = r[vp[i]];
    }
    q->s_center = r[vs[5]];
    q->s_half = r[vs[6]];
    q->kappa = r[vs[7]];
    q->load_inertia = r[vs[8]];
    q->m_s = r[vs[9]];
    q->T_s = r[vs[10]];
    const char* names[] = {"c_r", "sigma", "mu", "k0", "mu_sd", "s_center", "s_half", "kappa"};
    const double vals[] = {q->c_r, q->sigma, q->mu, q->k0, q->mu_sd, q->s_center, q->s_half, q->kappa};
    for (int i = 0; i < 8; i++)
        if (!isfinite(vals[i])) {
            snprintf(msg, MSG_LEN, "PredictorParams.%s%s must be finite, got %.17g", prefix, names[i], vals[i]);
            return 1;
        }
    for (int i = 0; i < PRED_NP; i++)
        if (!(isfinite(q->alpha[i]) && isfinite(q->beta[i]) && isfinite(q->p[i]))) {
            snprintf(msg, MSG_LEN, "%s%s contains non-finite values", prefix,
                     !isfinite(q->alpha[i]) ? "alpha" : (!isfinite(q->beta[i]) ? "beta" : "p"));
            return 1;
        }
    if (q->s_half <= 0) {
        snprintf(msg, MSG_LEN, "%ss_half must be > 0 [m]", prefix);
        return 1;
    }
    if (!(q->m_s > 0 && q->T_s > 0)) {
        snprintf(msg, MSG_LEN, "PredictorBlock: %sslider_mass_kg [kg] and %sT_s [s] must be positive", prefix, prefix);
        return 1;
    }
    return 0;
}

static int rebuild_params(Instance* c, char* msg)
{
    const double* r = c->s.r;
    ModelState* ms = &c->s.ms;
    if (read_setup(r, PRED_VR_SCALARS, PRED_VR_ALPHA, PRED_VR_BETA, PRED_VR_P, "", &ms->par, msg)) return 1;
#if PRED_EXTENDED
    if (read_setup(r, PRED_VR_BASE_SCALARS, PRED_VR_BASE_ALPHA, PRED_VR_BASE_BETA, PRED_VR_BASE_P, "baseline_",
                   &ms->base, msg))
        return 1;
    for (int i = 0; i < EFF_PHI_OFF[EFF_N]; i++) ms->phi[i] = r[EFF_PHI_VR[i]];
#if PRED_HAS_FILTER
    ms->filt[0] = r[VR_speed_filter_a];
    ms->filt[1] = r[VR_speed_filter_b0];
    ms->filt[2] = r[VR_speed_filter_b1];
#endif
#endif
    return 0;
}

/* Eq. 29 iterated at sub-steps of at most T_s over the communication step h (PredictorBlock._advance) */
static int advance(const PredictorParams* q, const double* r, double* v, double h, int has_F, double F, char* msg)
{
    double n_real = ceil(h / q->T_s - 1e-9);
    if ((MAX_SUBSTEPS > 0 && n_real > MAX_SUBSTEPS) || !(n_real < 1e15)) {
        snprintf(msg, MSG_LEN, "PredictorBlock: a step of %.17g s takes %.17g sub-steps of T_s = %.17g s, more than %d",
                 h, n_real, q->T_s, MAX_SUBSTEPS);
        return 1;
    }
    long n = n_real > 1.0 ? (long)n_real : 1;
    double w = *v;
    for (long k = 0; k < n; k++)
        w = one_step(q, w, r[VR_s], r[VR_V0], r[VR_load], r[VR_direction], h / n, has_F, F);
    *v = w;
    return 0;
}

#if PRED_EXTENDED
/* the effects' force at the current inputs and time (ExtendedPredictorBlock._force: their sum in order) */
static double extra_force(const Instance* c, double a_base)
{
    const double* r = c->s.r;
#if PRED_HAS_T
    const double T = r[VR_T];
#else
    const double T = NAN; /* no effect reads it */
#endif
    const double x[8] = {r[VR_t_now], r[VR_s], r[VR_V0], r[VR_load], r[VR_direction], T, r[VR_v_base], a_base};
    double F = 0.0;
    for (int e = 0; e < EFF_N; e++)
        F = F + l1b2k_effect_force(EFF_KIND[e], x, EFF_Q + EFF_Q_OFF[e], c->s.ms.phi + EFF_PHI_OFF[e]);
    return F;
}

/* second-order derivative at the middle of three samples (l1b2.predictor.effects.derivative_step) */
static double derivative_step(double v_prev, double v, double v_next, double h_prev, double h)
{
    return (-(h / (h_prev * (h_prev + h))) * v_prev + ((h - h_prev) / (h_prev * h)) * v
            + (h_prev / (h * (h_prev + h))) * v_next);
}
#endif

int model_initialize(Instance* c, char* msg)
{
    if (rebuild_params(c, msg)) return 1;
    if (core_check_inputs(c, msg)) return 1;
    double* r = c->s.r;
#if PRED_EXTENDED
    r[VR_v_base] = r[VR_v_raw] = r[VR_v_base_prev] = r[VR_v0];
    r[VR_h_prev] = 0.0;
#if PRED_HAS_FILTER
    {
        const double* f = c->s.ms.filt; /* filter_start_gain */
        const double gain = fabs(1.0 - f[0]) > 1e-9 ? (f[1] + f[2]) / (1.0 - f[0]) : 1.0;
        r[VR_v_state] = r[VR_v_raw] * gain;
    }
#else
    r[VR_v_state] = r[VR_v_raw] * 1.0;
#endif
    r[VR_F_extra] = extra_force(c, 0.0); /* a_base is not known before the first step */
#else
    r[VR_v_state] = r[VR_v0];
#endif
    outputs(c);
    return 0;
}

int model_do_step(Instance* c, double t, double h, char* msg)
{
    if (core_check_inputs(c, msg)) return 1;
    double* r = c->s.r;
#if PRED_EXTENDED
    const ModelState* ms = &c->s.ms;
    r[VR_t_now] = t;
    const double vb = r[VR_v_base];
    double vb_next = vb;
    if (advance(&ms->base, r, &vb_next, h, 0, 0.0, msg)) return 1;
    const double a_base = r[VR_h_prev] <= 0.0 ? (vb_next - vb) / h
                                              : derivative_step(r[VR_v_base_prev], vb, vb_next, r[VR_h_prev], h);
    const double F = extra_force(c, a_base);
    const double u_prev = r[VR_v_raw];
    double v_raw = u_prev;
    if (advance(&ms->par, r, &v_raw, h, EFF_N > 0, F, msg)) return 1;
    r[VR_F_extra] = F;
    r[VR_v_raw] = v_raw;
#if PRED_HAS_FILTER
    r[VR_v_state] = ms->filt[0] * r[VR_v_state] + ms->filt[1] * v_raw + ms->filt[2] * u_prev; /* filter_step */
#else
    r[VR_v_state] = v_raw;
#endif
    r[VR_v_base_prev] = vb;
    r[VR_v_base] = vb_next;
    r[VR_h_prev] = h;
    r[VR_t_now] = t + h;
#else
    (void)t;
    double v = r[VR_v_state];
    if (advance(&c->s.ms.par, r, &v, h, 0, 0.0, msg)) return 1;
    r[VR_v_state] = v;
#endif
    outputs(c);
    return 0;
}

void model_refresh(Instance* c) { outputs(c); }

void model_set_start_time(Instance* c, double t0)
{
#if PRED_EXTENDED
    c->s.r[VR_t_now] = t0;
#else
    (void)c;
    (void)t0;
#endif
}
