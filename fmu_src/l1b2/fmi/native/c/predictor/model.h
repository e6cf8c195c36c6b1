/* model.h - the state of the native Predictor FMU beyond its variables: the parameters the
 * instance was initialised with (l1b2.cosim.composite.PredictorBlock rebuilds them at initialisation) */
#ifndef L1B2_PREDICTOR_MODEL_H
#define L1B2_PREDICTOR_MODEL_H

typedef struct {
    double c_r, sigma, mu, k0, mu_sd;
    double alpha[PRED_NP], beta[PRED_NP], p[PRED_NP];
    double s_center, s_half, kappa, load_inertia, m_s, T_s;
} PredictorParams;

#ifndef PRED_EXTENDED
#define PRED_EXTENDED 0
#endif

typedef struct {
    PredictorParams par;
#if PRED_EXTENDED
    PredictorParams base; /* the baseline setup (gives v_base, a_base) */
    double phi[EFF_NPHI]; /* the effects' parameters, EFF_PHI_OFF[e] on for effect e */
    double filt[3];       /* the output filter's a, b0, b1 */
#endif
} ModelState;

#endif
