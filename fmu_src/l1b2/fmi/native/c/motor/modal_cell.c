/*
 * modal_cell.c - a cell of the stator's modal table built at run time, for axial forces or stator
 * parameters the cells baked at export do not cover.
 *
 * The operations of l1b2.physics.stator: _modal_properties_scalar (B2 frequency by secant iteration from the
 * Rayleigh estimate, tip coefficient from the closed-form normalisation of the centred mode shape; x ** n as
 * pow(x, n), as CPython computes it) at the TABLE_DEGREE + 1 Chebyshev-Lobatto nodes of the cell, and
 * ModalTable._build (_power_coefficients: mean taken out, numpy's pairwise sum for the mean, the
 * node-values-to-power-coefficients matrix baked at export). The matrix product is summed in index order
 * (numpy hands it to BLAS), so a cell may differ from Python's in the last bits of its coefficients.
 * A node where the secant iteration fails its checks (Python then takes a bracketing search, for axial forces
 * near buckling) makes the cell fail with a message.
 */
#include <math.h>
#include <stdio.h>

#include "fmu_core.h"

#define PI 3.141592653589793

typedef struct {
    double rhoS, L, half, EI, N;
} B2;

static void wavenumbers(const B2* b, double w, double* b1, double* b2)
{
    double h = b->N / (2.0 * b->EI);
    double root = sqrt(h * h + b->rhoS * w * w / b->EI);
    *b1 = sqrt(root - h);
    *b2 = sqrt(root + h);
}

static double characteristic(const B2* b, double w)
{
    double b1, b2;
    wavenumbers(b, w, &b1, &b2);
    return (-b1 * sin(b1 * b->half) * (b->EI * pow(b2, 2.0) - b->N)
            + b2 * tanh(b2 * b->half) * cos(b1 * b->half) * (b->EI * pow(b1, 2.0) + b->N)) / (b->EI * pow(b1, 3.0));
}

/* omega_b0 [rad/s] and eta_T at axial force P [N], dT [K] from the reference temperature (0 for the table cells:
 * ModalTable(sp, None)); 0, or 1 when the iteration fails */
static int b2_properties(const double* r, double P, double dT, double* wb_out, double* eta_out)
{
    B2 b;
    double area = r[VR_Stator_width_m] * r[VR_Stator_thickness_m];
    b.rhoS = r[VR_Stator_density_kg_m3] * area;
    b.L = r[VR_Stator_length_m];
    b.half = b.L / 2.0;
    b.EI = pow(2 * PI * (r[VR_Stator_f_b0_Hz] + r[VR_Stator_df_dT_b_Hz_per_K] * dT) * pow(b.L, 2.0)
               / pow(BETA_L_B2, 2.0), 2.0) * b.rhoS;
    b.N = -P;
    double L = b.L;
    double w0 = pow(BETA_L_B2, 2.0) / pow(L, 2.0) * sqrt(b.EI / b.rhoS);
    double lo = pow(w0, 2.0) + b.N * PHI_SLOPE_RATIO / pow(L, 2.0) / b.rhoS, hi = 1e-6 * pow(w0, 2.0);
    double wa = sqrt(hi > lo ? hi : lo); /* Python's max(lo, hi) */
    double w_rayleigh = wa, wb = wa * (1 + 1e-7);
    double fa = characteristic(&b, wa), fb = characteristic(&b, wb);
    for (int i = 0; i < 8; i++) {
        double wc = fb != fa ? wb - fb * (wb - wa) / (fb - fa) : wb;
        if (wc == wb) break;
        wa = wb;
        fa = fb;
        wb = wc;
        fb = characteristic(&b, wc);
    }
    if (!(isfinite(wb) && wb > 0 && fabs(fb) < 1e-9 && fabs(wb / w_rayleigh - 1) < 0.5)) return 1;
    double b1, b2;
    wavenumbers(&b, wb, &b1, &b2);
    double half = b.half;
    double s1 = sin(b1 * half), sh2 = sinh(b2 * half);
    double Ec = pow(b1, 2.0) * s1 / (pow(b2, 2.0) * sh2);
    double i_ss = half - sin(2 * b1 * half) / (2 * b1);
    double i_hh = sinh(2 * b2 * half) / (2 * b2) - half;
    double i_sh = 2 * (b2 * s1 * cosh(b2 * half) - b1 * cos(b1 * half) * sh2) / (b1 * b1 + b2 * b2);
    double norm2 = i_ss + 2 * Ec * i_sh + Ec * Ec * i_hh;
    double eta = fabs(s1 + Ec * sh2) * sqrt(L / norm2);
    if (!isfinite(eta)) return 1;
    *wb_out = wb;
    *eta_out = eta;
    return 0;
}

/* numpy's mean of TABLE_ROWS values: pairwise sum (8 accumulators when n >= 8, then the rest in order) / n */
static double np_mean(const double* a)
{
    const int n = TABLE_ROWS;
    double res;
    if (n < 8) {
        res = 0.0; /* numpy starts at -0.0 + a[0]...; the same for finite values */
        for (int i = 0; i < n; i++) res += a[i];
    } else {
        double q[8];
        for (int j = 0; j < 8; j++) q[j] = a[j];
        int i = 8;
        for (; i < n - (n % 8); i += 8)
            for (int j = 0; j < 8; j++) q[j] += a[i + j];
        res = ((q[0] + q[1]) + (q[2] + q[3])) + ((q[4] + q[5]) + (q[6] + q[7]));
        for (; i < n; i++) res += a[i];
    }
    return res / n;
}

static void power_coefficients(const double* values, double* coef)
{
    double mean = np_mean(values), d[TABLE_ROWS];
    for (int j = 0; j < TABLE_ROWS; j++) d[j] = values[j] - mean;
    for (int i = 0; i < TABLE_ROWS; i++) {
        double s = 0.0;
        for (int j = 0; j < TABLE_ROWS; j++) s += TO_POWER[i][j] * d[j];
        coef[i] = s;
    }
    coef[TABLE_ROWS - 1] += mean;
}

/* cell k (TABLE_ROWS rows of (B2 frequency, tip coefficient) power coefficients, highest first); 0, or 1 */
int modal_cell_build(const double* r, double k, double* cell, char* msg)
{
    double wb[TABLE_ROWS], eta[TABLE_ROWS], cw[TABLE_ROWS], ce[TABLE_ROWS];
    const double w = TABLE_CELL_N;
    if (!(k * w >= 0.0)) {
        snprintf(msg, MSG_LEN, "StatorBlock: no modal-table cell %.17g (axial force below 0 N)", k);
        return 1;
    }
    for (int i = 0; i < TABLE_ROWS; i++) {
        double P = k * w + 0.5 * (LOBATTO_X[i] + 1.0) * w;
        if (b2_properties(r, P, 0.0, &wb[i], &eta[i])) {
            snprintf(msg, MSG_LEN, "StatorBlock: the B2 frequency at the axial force P = %.17g N did not converge "
                     "in the native FMU (near buckling; the Python L1B2Motor.fmu searches further)", P);
            return 1;
        }
    }
    power_coefficients(wb, cw);
    power_coefficients(eta, ce);
    for (int i = 0; i < TABLE_ROWS; i++) {
        cell[2 * i] = cw[i];
        cell[2 * i + 1] = ce[i];
    }
    return 0;
}

/* the B2 frequency and tip coefficient at axial force P [N] and stator temperature T [degC], evaluated directly
 * (StatorBlock._update_props with a temperature-dependent B2 mode: modal_properties(sp, P, T)); 0, or 1 */
int modal_b2_direct(const double* r, double P, double T, double* wb, double* eta, char* msg)
{
    if (b2_properties(r, P, T - r[VR_Stator_T_ref_degC], wb, eta)) {
        snprintf(msg, MSG_LEN, "StatorBlock: the B2 frequency at the axial force P = %.17g N and the stator "
                 "temperature %.17g degC did not converge in the native FMU (near buckling; the Python "
                 "L1B2Motor.fmu searches further)", P, T);
        return 1;
    }
    return 0;
}
