/* model.h - the state of the native L1B2Motor FMU beyond its variables: the fused state vector of
 * l1b2.physics.coupled (MOTOR_NX entries), its parameter vector, the modal-table cell in use, the
 * internal step and the driver's outputs (l1b2.cosim.engine.FusedSteps holds the same), and the modal-table
 * cells built at run time (part of the state: they follow from the parameters, fixed after initialisation) */
#ifndef L1B2_MOTOR_MODEL_H
#define L1B2_MOTOR_MODEL_H

#define CELL_CACHE_N 64 /* modal-table cells built at run time, by cell number modulo CELL_CACHE_N */

typedef struct {
    double x[MOTOR_NX];
    double p[MOTOR_NP];
    double cell_k;        /* the modal-table cell the kernel holds (-1: none yet) */
    double h_int;         /* internal step [s] */
    double V0_phase, V_inv1, omega0;
    double driven[5];     /* the driver's inputs (V_s, duty, f_s, T) at its last evaluation, and 1 when valid */
    double baked_ok;      /* 1: the baked cells apply (the stator parameters of the export) */
    double cache_k[CELL_CACHE_N];
    double cache[CELL_CACHE_N][2 * TABLE_ROWS];
} ModelState;

#endif
