/*
 * motor_model.c - the coupled motor of the native L1B2Motor FMU.
 *
 * The physics per step is motor_kernels.h, generated from the Python source of
 * l1b2.physics.coupled.motor_substeps and the kernels it calls
 * (l1b2.fmi.native.translate): the operations of the Python FMU's fused step.
 * This file is the rest of l1b2.cosim.composite.MotorBlock and
 * l1b2.cosim.engine.FusedSteps: initialisation of the four subsystems
 * (InProcessMotor.initialize), the driver (l1b2.physics.driver.driver_output),
 * the communication step (n internal steps, the modal-table cells), and the
 * outputs and sub-block variables read from the state vector.
 *
 * The modal table's cells (B2 frequency and tip coefficient against the axial
 * force) are computed at export by l1b2.physics.stator.ModalTable and baked into
 * model_data.h for the stator parameters of the export (0 to 60 N); other cells,
 * or all cells for other stator parameters, are built at run time (modal_cell.c).
 * With a temperature-dependent B2 mode the B2 properties are evaluated directly at every internal step
 * (thermal_substep), as the stator block does; the interface's numerical reference kernel is refused at
 * initialisation.
 */
#include <math.h>
#include <stdio.h>

#include "fmu_core.h"
#include "motor_kernels.h"

#define PI 3.141592653589793

int modal_cell_build(const double* r, double k, double* cell, char* msg); /* modal_cell.c */
int modal_b2_direct(const double* r, double P, double T, double* wb, double* eta, char* msg);

/* cell k of the modal table: baked at export when the stator parameters are the export's, else built here
 * (kept in the state's cache); NULL with the reason in msg when it cannot be built */
static const double* get_cell(Instance* c, double k, char* msg)
{
    ModelState* m = &c->s.ms;
    if (m->baked_ok != 0.0 && k >= TABLE_K0 && k < TABLE_K0 + TABLE_NCELL) return MOTOR_TABLE[(long)k - TABLE_K0];
    if (!(k >= 0.0 && k < 1e15)) {
        snprintf(msg, MSG_LEN, "StatorBlock: no modal-table cell for the axial force cell %.17g", k);
        return 0;
    }
    int slot = (int)fmod(k, CELL_CACHE_N);
    if (m->cache_k[slot] != k) {
        if (modal_cell_build(c->s.r, k, m->cache[slot], msg)) return 0;
        m->cache_k[slot] = k;
    }
    return m->cache[slot];
}

/* l1b2.physics.driver.driver_output (the tank's exact phasor gain on the fundamental of Eq. 1) */
static void driver(Instance* c)
{
    double* r = c->s.r;
    ModelState* m = &c->s.ms;
    double f = r[VR_f_s], T = r[VR_T];
    double omega = 2.0 * PI * f;
    double L = r[VR_Driver_L_H] * (1.0 + r[VR_Driver_L_temp_coeff_per_K] * (T - r[VR_Driver_T_ref_degC])
                                   + r[VR_Driver_L_freq_coeff_per_Hz] * (f - r[VR_Driver_f_ref_Hz]));
    double C1 = r[VR_Driver_C1_F] * (1.0 + r[VR_Driver_C1_freq_coeff_per_Hz] * (f - r[VR_Driver_f_ref_Hz]));
    double C = C1 + r[VR_Driver_C_m_F];
    double R = r[VR_Driver_R_m_ohm];
    /* H = 1 / (1 - w^2 L C + j w L / R) */
    double dre = 1.0 - omega * omega * L * C, dim = omega * L / R;
    l1b2_cplx H = l1b2_cdiv(l1b2_c(1.0, 0.0), l1b2_c(dre, dim));
    double V1 = 4.0 / PI * sin(0.5 * PI * r[VR_duty]) * r[VR_V_s];
    double V0 = l1b2_cabs(H) * V1;
    double Vsat = r[VR_Driver_V0_sat_V];
    if (Vsat > 0) V0 = Vsat * tanh(V0 / Vsat);
    double arg = 1.0 / (L * C) - 1.0 / ((R * R) * (C * C)), scale = 1.0 / (L * C);
    if (fabs(arg) <= 1e-12 * scale) arg = 0.0;
    double w0 = arg >= 0 ? sqrt(arg) : NAN;
    m->x[X_V0] = V0;
    m->x[X_OMEGA] = omega;
    m->V0_phase = l1b2_cphase(H);
    m->V_inv1 = V1;
    m->omega0 = isfinite(w0) ? w0 : 0.0;
    r[VR_Driver_V_s] = r[VR_V_s];
    r[VR_Driver_duty] = r[VR_duty];
    r[VR_Driver_f_s] = r[VR_f_s];
    r[VR_Driver_T] = r[VR_T];
}

/* the system inputs the steps hold (FusedSteps.set_inputs); 0, or 1 with the blocks' error in msg */
static int held_inputs(Instance* c, char* msg)
{
    ModelState* m = &c->s.ms;
    double* x = m->x;
    const double* r = c->s.r;
    const double u[4] = {r[VR_V_s], r[VR_duty], r[VR_f_s], r[VR_T]};
    /* the driver is algebraic: with the inputs of its last evaluation its outputs stand (DriverBlock's memo;
     * its parameters are fixed after initialisation) */
    if (!(m->driven[4] != 0.0 && u[0] == m->driven[0] && u[1] == m->driven[1] && u[2] == m->driven[2]
          && u[3] == m->driven[3])) {
        driver(c);
        for (int i = 0; i < 4; i++) m->driven[i] = u[i];
        m->driven[4] = 1.0;
    }
    x[X_DIR] = r[VR_direction];
    x[X_T_AMB] = r[VR_T];
    x[X_M_LOAD] = r[VR_m_load];
    const char* names[] = {"V0", "omega"};
    const double lo[] = {0.0, 1e3}, hi[] = {2000.0, 1e7};
    for (int i = 0; i < 2; i++) {
        double v = x[i == 0 ? X_V0 : X_OMEGA];
        if (!(lo[i] <= v && v <= hi[i])) {
            snprintf(msg, MSG_LEN, "StatorBlock: input %s [%s] = %.17g is %s", names[i], i == 0 ? "V" : "rad/s", v,
                     !isfinite(v) ? "not finite" : (v < lo[i] ? "below the range" : "above the range"));
            return 1;
        }
    }
    return 0;
}

static void publish(Instance* c)
{
    double* r = c->s.r;
    const double* x = c->s.ms.x;
    for (int i = 0; i < MOTOR_NMAP; i++) r[MOTOR_MAP_VR[i]] = x[MOTOR_MAP_X[i]];
    r[VR_Stator_v_tip] = x[X_OMEGA] * x[X_U_W]; /* omega * U_w */
    r[VR_Stator_f_b] = x[X_W_B0] / (2 * PI);
    r[VR_Driver_V0_phase] = c->s.ms.V0_phase;
    r[VR_Driver_V_inv1] = c->s.ms.V_inv1;
    r[VR_Driver_omega0] = c->s.ms.omega0;
}

/* the parameter vector of l1b2.physics.coupled.parameter_vector from the FMU's parameters */
static void parameters(Instance* c)
{
    const double* r = c->s.r;
    double* p = c->s.ms.p;
    for (int i = 0; i < MOTOR_NP; i++) p[i] = MOTOR_PARAM_VR[i] >= 0 ? r[MOTOR_PARAM_VR[i]] : 0.0;
    double area = r[VR_Stator_width_m] * r[VR_Stator_thickness_m];
    p[P_M_L] = r[VR_Stator_density_kg_m3] * area * r[VR_Stator_length_m] / 2.0;
    p[P_M_B] = r[VR_Stator_density_kg_m3] * area * r[VR_Stator_length_m];
    p[P_B2_THERMAL] = r[VR_Stator_df_dT_b_Hz_per_K] != 0.0 ? 1.0 : 0.0;
    p[P_PURE_SLIP] = r[VR_Interface_pure_slip] != 0.0 ? 1.0 : 0.0;
}

static int table_applies(Instance* c, char* msg)
{
    const double* r = c->s.r;
    c->s.ms.baked_ok = 1.0; /* the baked cells hold for the stator parameters of the export */
    for (int i = 0; i < TABLE_NCHECK; i++)
        if (r[TABLE_CHECK_VR[i]] != TABLE_CHECK_VALUE[i]) c->s.ms.baked_ok = 0.0;
    for (int i = 0; i < CELL_CACHE_N; i++) c->s.ms.cache_k[i] = -1.0;
    if (r[VR_Interface_quadrature] != 0.0) {
        snprintf(msg, MSG_LEN, "Interface.quadrature = true: the numerical reference kernel is not in the native "
                 "FMU (use the Python L1B2Motor.fmu)");
        return 1;
    }
    return 0;
}

/* InProcessMotor.initialize, then FusedSteps.load */
int model_initialize(Instance* c, char* msg)
{
    double* r = c->s.r;
    ModelState* m = &c->s.ms;
    double* x = m->x;
    const double* p = m->p;
    if (core_check_inputs(c, msg) || table_applies(c, msg)) return 1;
    parameters(c);
    m->h_int = r[VR_internal_step_s];
    for (int i = 0; i < MOTOR_NX; i++) x[i] = 0.0;
    m->driven[4] = 0.0;
    if (held_inputs(c, msg)) return 1;
    double s0 = r[VR_Slider_s0], v0 = r[VR_Slider_v0], T = r[VR_T];
    if (!(p[P_S_MIN] <= s0 && s0 <= p[P_S_MAX])) {
        snprintf(msg, MSG_LEN, "SliderBlock: s0 [m] = %.17g outside the stroke [%.17g, %.17g]", s0, p[P_S_MIN],
                 p[P_S_MAX]);
        return 1;
    }
    /* stator (StatorBlock.initialize: temperature, modal properties at P(s0), tip motion of the zero phasors) */
    double T_st = p[P_TAU] > 0 ? r[VR_Stator_T_st0] : T;
    double P = l1b2_max(p[P_P0] + p[P_K_PRE] * l1b2k_bar_deviation_scalar(
        s0, p[P_HALF], p[P_DEV1], p[P_DEV2], p[P_DEV3], p[P_WAVE_A], p[P_WAVE_P], p[P_BUMP_A], p[P_BUMP_C],
        p[P_BUMP_W]), 0.0);
    double wb, eta;
    if (p[P_B2_THERMAL] != 0.0) { /* modal_properties(sp, P, T_st) */
        if (modal_b2_direct(r, P, T_st, &wb, &eta, msg)) return 1;
        eta = fabs(eta);
    } else {
        double k = floor(P / TABLE_CELL_N);
        const double* cell = get_cell(c, k, msg);
        if (!cell) return 1;
        l1b2_tup2 props = l1b2k_table_lookup(cell, P);
        wb = props.v[0];
        eta = fabs(props.v[1]);
    }
    double w_l0 = l1b2k_l1_omega_scalar(p[P_F_L0], p[P_DF_L], T_st - p[P_T_REF]);
    l1b2_tup2 kl = l1b2k_stiffness_damping(p[P_M_L], w_l0, p[P_ZETA_L]);
    l1b2_tup2 kb = l1b2k_stiffness_damping(p[P_M_B], wb, p[P_ZETA_B]);
    x[X_T_ST] = T_st;
    x[X_K_L] = kl.v[0];
    x[X_C_L] = kl.v[1];
    x[X_K_B] = kb.v[0];
    x[X_C_B] = kb.v[1];
    x[X_ETA] = eta;
    x[X_W_L0] = w_l0;
    x[X_W_B0] = wb;
    x[X_PROPS_T] = T_st;
    l1b2_tup5 tip = l1b2k_tip_motion_scalar(l1b2_c(0.0, 0.0), l1b2_c(0.0, 0.0), eta);
    for (int i = 0; i < 5; i++) x[X_U_L + i] = tip.v[i];
    x[X_F_P] = p[P_ALPHA0] * P;
    x[X_P_AX] = P;
    x[X_S_IN] = s0;
    x[X_V_IN] = v0;
    /* interface (InterfaceBlock.initialize: its input checks, then the kernel) */
    const double in[] = {x[X_U_L], x[X_U_W], x[X_DELTA], x[X_OMEGA], v0, x[X_F_P]};
    const char* in_names[] = {"U_l", "U_w", "delta", "omega", "v", "F_p"};
    const double in_lo[] = {0.0, 0.0, -10.0, 1e3, -10.0, 0.0}, in_hi[] = {1e-3, 1e-3, 10.0, 1e7, 10.0, 1e4};
    for (int i = 0; i < 6; i++)
        if (!(in_lo[i] <= in[i] && in[i] <= in_hi[i])) {
            snprintf(msg, MSG_LEN, "InterfaceBlock: input %s = %.17g outside [%g, %g]", in_names[i], in[i], in_lo[i],
                     in_hi[i]);
            return 1;
        }
    l1b2_tup8 f = l1b2k_period_integrals(in[0], in[1], in[2], in[3], in[4], in[5], p[P_K_E], p[P_U_M], p[P_MU_P],
                                         p[P_SIGMA], p[P_PURE_SLIP]);
    for (int i = 0; i < 8; i++) x[X_F_D + i] = f.v[i];
    /* slider (SliderBlock.initialize; its stroke check comes first here) */
    x[X_V] = v0;
    x[X_S] = s0;
    x[X_STUCK] = v0 == 0.0 ? 1.0 : 0.0;
    x[X_STOP] = 0.0;
    x[X_ACC] = 0.0;
    m->cell_k = -1.0;
    publish(c);
    return 0;
}

/* A temperature-dependent B2 mode: the stator block evaluates the modal properties directly at the step's axial
 * force and stator temperature (where the fused kernel hands the step to the blocks). One internal step of the
 * kernel with them: a cell whose interpolant is the constant (omega_b0, eta_T) (Horner gives the constant
 * exactly), the kernel's thermal hand-over switched off. 0: done; 1: failed, the reason in msg; 2: an internal
 * signal left the blocks' ranges (the state is that before the step). */
static int thermal_substep(Instance* c, double hs, char* msg)
{
    ModelState* m = &c->s.ms;
    double* x = m->x;
    const double* p = m->p;
    double T_st = x[X_T_ST];
    if (p[P_TAU] > 0.0 || p[P_HEAT] != 0.0)
        T_st = l1b2k_temperature_step_scalar(T_st, x[X_T_AMB], x[X_V0], p[P_TAU], p[P_HEAT], hs);
    else
        T_st = x[X_T_AMB];
    double P = l1b2_max(p[P_P0] + p[P_K_PRE] * l1b2k_bar_deviation_scalar(
        x[X_S], p[P_HALF], p[P_DEV1], p[P_DEV2], p[P_DEV3], p[P_WAVE_A], p[P_WAVE_P], p[P_BUMP_A], p[P_BUMP_C],
        p[P_BUMP_W]), 0.0);
    double wb, eta, cell[2 * TABLE_ROWS] = {0.0}, q[MOTOR_NP];
    if (modal_b2_direct(c->s.r, P, T_st, &wb, &eta, msg)) return 1;
    cell[2 * (TABLE_ROWS - 1)] = wb;
    cell[2 * (TABLE_ROWS - 1) + 1] = eta;
    for (int i = 0; i < MOTOR_NP; i++) q[i] = p[i];
    q[P_B2_THERMAL] = 0.0;
    return l1b2k_motor_substeps(x, q, cell, (long)floor(P / TABLE_CELL_N), 1, hs) == 1 ? 0 : 2;
}

/* MotorBlock.do_step through FusedSteps.advance */
int model_do_step(Instance* c, double t, double h, char* msg)
{
    (void)t;
    ModelState* m = &c->s.ms;
    double* x = m->x;
    if (core_check_inputs(c, msg)) return 1;
    double n_real = nearbyint(h / m->h_int); /* Python's round(): half to even */
    if (MAX_SUBSTEPS > 0 && n_real > MAX_SUBSTEPS) {
        snprintf(msg, MSG_LEN, "MotorBlock: a step of %.17g s takes %.17g internal steps of internal_step_s = "
                 "%.17g s, more than %d", h, n_real, m->h_int, MAX_SUBSTEPS);
        return 1;
    }
    if (!(n_real < 1e15)) {
        snprintf(msg, MSG_LEN, "MotorBlock: a step of %.17g s takes %.17g internal steps", h, n_real);
        return 1;
    }
    long n = n_real > 1.0 ? (long)n_real : 1;
    double hs = h / n;
    if (held_inputs(c, msg)) return 1;
    long done = 0;
    while (done < n && m->p[P_B2_THERMAL] != 0.0) {
        int rc = thermal_substep(c, hs, msg);
        if (rc == 1) return 1;
        if (rc == 2) break; /* the kernel below reports the ranges */
        done++;
    }
    while (done < n) {
        const double* cell = m->cell_k >= 0 ? get_cell(c, m->cell_k, msg) : MOTOR_TABLE[0];
        if (!cell) return 1;
        long k = l1b2k_motor_substeps(x, m->p, cell, m->cell_k >= 0 ? (long)m->cell_k : -1, n - done, hs);
        done += k;
        if (done == n) break;
        if (x[X_REASON] == 1.0) { /* REASON_CELL */
            if (!get_cell(c, x[X_NEED_CELL], msg)) return 1;
            m->cell_k = x[X_NEED_CELL];
            continue;
        }
        snprintf(msg, MSG_LEN, "an internal signal left the range the subsystem blocks accept (stator position "
                 "s = %.17g m, tip amplitudes U_l = %.17g m, U_w = %.17g m, phase delta = %.17g rad, speed "
                 "v = %.17g m/s, axial force F_p = %.17g N, driving force F_d = %.17g N)", x[X_S], x[X_U_L],
                 x[X_U_W], x[X_DELTA], x[X_V], x[X_F_P], x[X_F_D]);
        publish(c);
        return 1;
    }
    publish(c);
    return 0;
}

void model_refresh(Instance* c) { publish(c); }

void model_set_start_time(Instance* c, double t0) { (void)c; (void)t0; }
