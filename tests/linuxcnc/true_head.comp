component pige_true_head "pige_sym test: the TRUE head or mixed machine of a simulated five-axis machine and its touch probe";
description """
The true machine of tests/linuxcnc/test_linuxcnc_head.py, written in the test from CONVENTIONS 2, 3 and 7
(no pige code).  Joints 3 and 4 are rotary axes, each with its true line (a point and a unit direction,
exact Rodrigues rotations) and a role: 1 the head axis that carries the spindle, 2 the head axis that
carries that one, 3 the table axis on the bed, 4 the table axis it carries (0: none).  With identity
kinematics the linear joints less the tool length are where the stylus-tip centre would be with the head at
its reference pose; the head axes turn the tip by +(sense * joint + zero), inner axis first; the table axes
turned the sphere by -(sense * joint + zero), so turning the tip by the same angles, outer axis first, takes
it into the table's coordinates.  The probe trips when that point is within trip-radius of the sphere's centre.
""";
pin in float joint_x "joint 0 feedback [mm]";
pin in float joint_y "joint 1 feedback [mm]";
pin in float joint_z "joint 2 feedback [mm]: the spindle's gauge line";
pin in float joint_r#[2] "joints 3 and 4 feedback [deg]";
pin in s32 role#[2] "1 head inner, 2 head outer, 3 table outer, 4 table inner";
pin in float px#[2]; pin in float py#[2]; pin in float pz#[2];
pin in float ux#[2]; pin in float uy#[2]; pin in float uz#[2];
pin in float zero#[2] "zero-position error [rad]";
pin in float sense#[2] "commanded sense: negative -1, else +1";
pin in float b0_x "stylus-tip centre at the reference pose: nominal head pivot + tool [mm]";
pin in float b0_y; pin in float b0_z;
pin in float tool_length "gauge line to the tool's controlled point (G43) [mm]";
pin in float sphere_x; pin in float sphere_y; pin in float sphere_z;
pin in float trip_radius "R + r - pre-travel [mm]";
pin out bit probe "tip centre within trip-radius of the sphere centre";
pin out float tip_x "stylus-tip centre in table coordinates [mm]";
pin out float tip_y;
pin out float tip_z;
pin out float gap "distance of the tip centre from the sphere centre minus trip-radius [mm]";
pin out float trip_gap "gap at the last rising edge of probe [mm]";
pin out s32 trips "rising edges of probe";
pin out float clock "simulated time: the sum of the servo periods since loading [s]";
function _;
license "GPL";
;;
#include <rtapi_math.h>

/* y <- q + R(u, phi) (y - q): Rodrigues rotation of y about the line through q along the unit vector u */
static void turn(double y[3], const double q[3], const double u[3], double phi)
{
    double v[3] = {y[0] - q[0], y[1] - q[1], y[2] - q[2]};
    double c = cos(phi), s = sin(phi);
    double d = u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
    double w[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    int i;
    for (i = 0; i < 3; i++) y[i] = q[i] + c * v[i] + s * w[i] + (1.0 - c) * d * u[i];
}

FUNCTION(_) {
    double b[3] = {b0_x, b0_y, b0_z}, y[3], q[3], u[3];
    double dx, dy, dz, g, phi;
    int r, k, was = probe;
    clock = clock + fperiod;
    for (r = 1; r <= 4; r++) {
        for (k = 0; k < 2; k++) {
            if (role(k) != r) continue;
            q[0] = px(k); q[1] = py(k); q[2] = pz(k);
            u[0] = ux(k); u[1] = uy(k); u[2] = uz(k);
            phi = (sense(k) < 0.0 ? -1.0 : 1.0) * joint_r(k) * M_PI / 180.0 + zero(k);
            turn(r <= 2 ? b : y, q, u, phi);
        }
        if (r == 2) {  /* the head has turned the tip: b = T(theta)(b0); now the machine point of the tip */
            y[0] = joint_x + b[0] - b0_x;
            y[1] = joint_y + b[1] - b0_y;
            y[2] = joint_z - tool_length + b[2] - b0_z;
        }
    }
    tip_x = y[0]; tip_y = y[1]; tip_z = y[2];
    dx = y[0] - sphere_x; dy = y[1] - sphere_y; dz = y[2] - sphere_z;
    g = sqrt(dx * dx + dy * dy + dz * dz) - trip_radius;
    gap = g;
    probe = g <= 0.0;
    if (probe && !was) { trip_gap = g; trips = trips + 1; }
}
