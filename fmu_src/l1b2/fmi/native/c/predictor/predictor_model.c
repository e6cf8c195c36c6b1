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

static double one_step(const PredictorParams* q, double v, double s, double V0, double load, double d, double dt)
{
    double vp = d * v;
    double D, X, Fr;
    force_parts(q, s, V0, d * load, q->m_s, &D, &X, &Fr);
    double m_eff = q->load_inertia >= 0.5 ? q->m_s + fabs(load) : q->m_s + 0.0 * load;
    double h = dt / m_eff;
    return d * step_drive(vp, D, X, Fr, h);
}

static double steady_state(const PredictorParams* q, double s, double V0, double load, double d)
{
    double D, X, Fr;
    force_parts(q, s, V0, d * load, q->m_s, &D, &X, &Fr);
    double fwd = X - Fr, bwd = X + Fr;
    double vp = fwd > 0 ? fwd / D : (bwd < 0 ? bwd / D : 0.0);
    if (!(D > 0)) vp = NAN;
    return d * vp;
}

static void outputs(Instance* c)
{
    double* r = c->s.r;
    r[VR_v] = r[VR_v_state];
    r[VR_v_steady] = steady_state(&c->s.ms.par, r[VR_s], r[VR_V0], r[VR_load], r[VR_direction]);
}

/* the parameters from the variables, checked as PredictorParams and PredictorBlock check them */
static int rebuild_params(Instance* c, char* msg)
{
    const double* r = c->s.r;
    PredictorParams* q = &c->s.ms.par;
    q->c_r = r[VR_c_r];
    q->sigma = r[VR_sigma];
    q->mu = r[VR_mu];
    q->k0 = r[VR_k0];
    q->mu_sd = r[VR_mu_sd];
    for (int i = 0; i < PRED_NP; i++) {
        q->alpha[i] = r[PRED_VR_ALPHA[i]];
        q->beta[i] = r[PRED_VR_BETA[i]];
        q->p[i] = r[PRED_VR_P[i]];
    }
    q->s_center = r[VR_s_center];
    q->s_half = r[VR_s_half];
    q->kappa = r[VR_kappa];
    q->load_inertia = r[VR_load_inertia];
    q->m_s = r[VR_slider_mass_kg];
    q->T_s = r[VR_T_s];
    const char* names[] = {"c_r", "sigma", "mu", "k0", "mu_sd", "s_center", "s_half", "kappa"};
    const double vals[] = {q->c_r, q->sigma, q->mu, q->k0, q->mu_sd, q->s_center, q->s_half, q->kappa};
    for (int i = 0; i < 8; i++)
        if (!isfinite(vals[i])) {
            snprintf(msg, MSG_LEN, "PredictorParams.%s must be finite, got %.17g", names[i], vals[i]);
            return 1;
        }
    for (int i = 0; i < PRED_NP; i++)
        if (!(isfinite(q->alpha[i]) && isfinite(q->beta[i]) && isfinite(q->p[i]))) {
            snprintf(msg, MSG_LEN, "%s contains non-finite values",
                     !isfinite(q->alpha[i]) ? "alpha" : (!isfinite(q->beta[i]) ? "beta" : "p"));
            return 1;
        }
    if (q->s_half <= 0) {
        snprintf(msg, MSG_LEN, "s_half must be > 0 [m]");
        return 1;
    }
    if (!(q->m_s > 0 && q->T_s > 0)) {
        snprintf(msg, MSG_LEN, "PredictorBlock: slider_mass_kg [kg] and T_s [s] must be positive");
        return 1;
    }
    return 0;
}

int model_initialize(Instance* c, char* msg)
{
    if (rebuild_params(c, msg)) return 1;
    if (core_check_inputs(c, msg)) return 1;
    c->s.r[VR_v_state] = c->s.r[VR_v0];
    outputs(c);
    return 0;
}

int model_do_step(Instance* c, double t, double h, char* msg)
{
    (void)t;
    if (core_check_inputs(c, msg)) return 1;
    double* r = c->s.r;
    const PredictorParams* q = &c->s.ms.par;
    double n_real = ceil(h / q->T_s - 1e-9);
    if ((MAX_SUBSTEPS > 0 && n_real > MAX_SUBSTEPS) || !(n_real < 1e15)) {
        snprintf(msg, MSG_LEN, "PredictorBlock: a step of %.17g s takes %.17g sub-steps of T_s = %.17g s, more than %d",
                 h, n_real, q->T_s, MAX_SUBSTEPS);
        return 1;
    }
    long n = n_real > 1.0 ? (long)n_real : 1;
    double v = r[VR_v_state];
    for (long k = 0; k < n; k++) v = one_step(q, v, r[VR_s], r[VR_V0], r[VR_load], r[VR_direction], h / n);
    r[VR_v_state] = v;
    outputs(c);
    return 0;
}

void model_refresh(Instance* c) { outputs(c); }

void model_set_start_time(Instance* c, double t0) { (void)c; (void)t0; }
