/*
 * test_cone_proofs.c — the proofs about one triangle (core/kd_cone_proof.c):
 * random triangles and cones aimed at the proofs' edges, every verdict
 * other than UNKNOWN checked with float rays through the cone.
 */
#include "test_cone_util.h"

static double rnd_log(double lo, double hi) { return lo * pow(hi / lo, rnd()); }

static void rnd_unit(double d[3]) {
    double l;
    do {
        for (int k = 0; k < 3; k++)
            d[k] = 2.0 * rnd() - 1.0;
        l = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    } while (l < 0.1 || l > 1.0);
    for (int k = 0; k < 3; k++)
        d[k] /= l;
}

/* A float direction within angle b of axis (on the rim half the time). */
static void rnd_in_cone(const double a[3], double b, float d[3]) {
    double b1[3], b2[3], v[3];
    unit_basis(a, b1, b2);
    const double th = rnd() < 0.5 ? b : b * sqrt(rnd()), ph = 6.283185307179586 * rnd();
    for (int k = 0; k < 3; k++)
        v[k] = cos(th) * a[k] + sin(th) * (cos(ph) * b1[k] + sin(ph) * b2[k]);
    const double l = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int k = 0; k < 3; k++)
        d[k] = (float)(v[k] / l);
}

/* Random triangles and cones aimed at the proofs' edges: a point's own
 * surface with the apex 1 to 1e4 ulps of the triangle's size above it
 * (acne territory) and cones leaving it at any angle, and triangles across
 * the cone near its rim, near tmax and at grazing angles; every verdict
 * other than UNKNOWN is checked with float rays through the cone (half of
 * them on its rim) against kd_tri_intersect. */
static void test_proofs(void) {
    rng_state = 2024;
    long verdicts[3] = {0, 0, 0}, rays = 0, wrong = 0;
    for (int trial = 0; trial < 40000 && wrong < 5; trial++) {
        const double L = rnd_log(1e-2, 1e5);
        float apex[3], tri[9];
        double axis[3], nrm[3], b1[3], b2[3];
        for (int k = 0; k < 3; k++)
            apex[k] = (float)((2.0 * rnd() - 1.0) * L);
        const int own = trial % 2 == 0;
        if (rnd() < 0.3) { /* an axis-aligned plane */
            nrm[0] = nrm[1] = nrm[2] = 0.0;
            nrm[trial % 3] = rnd() < 0.5 ? 1.0 : -1.0;
        } else {
            rnd_unit(nrm);
        }
        unit_basis(nrm, b1, b2);
        const double M = own ? L * rnd_log(1e-3, 10.0) : L * rnd_log(1e-3, 1.0);
        double tmax_lo;
        if (own) { /* a plane just below the apex, the apex over the triangle */
            const double h = M * 0x1p-24 * rnd_log(1.0, 1e4);
            const double ph = 6.283185307179586 * rnd();
            for (int i = 0; i < 3; i++) {
                const double an = ph + 2.0944 * i + 0.5 * (rnd() - 0.5);
                const double r = M * (0.3 + rnd());
                for (int k = 0; k < 3; k++)
                    tri[3 * i + k] = (float)(apex[k] - h * nrm[k] +
                                             r * (cos(an) * b1[k] + sin(an) * b2[k]));
            }
            for (int k = 0; k < 3; k++) /* mostly leaving the plane */
                axis[k] = nrm[k] * (rnd() * 1.3 - 0.3) + (rnd() - 0.5);
            tmax_lo = L * rnd_log(1e-3, 10.0);
        } else { /* a triangle ahead, the cone through it, near it or grazing */
            double c[3], dir[3];
            rnd_unit(dir);
            const double dist = M * rnd_log(0.5, 100.0);
            for (int k = 0; k < 3; k++)
                c[k] = apex[k] + dist * dir[k];
            for (int i = 0; i < 3; i++) {
                const double an = 2.0944 * i + 0.7 * (rnd() - 0.5);
                const double r = M * (0.3 + rnd());
                for (int k = 0; k < 3; k++)
                    tri[3 * i + k] =
                        (float)(c[k] + r * (cos(an) * b1[k] + sin(an) * b2[k]));
            }
            const double off = M / dist * (rnd() * 1.5);
            double e1[3], e2[3];
            unit_basis(dir, e1, e2);
            for (int k = 0; k < 3; k++)
                axis[k] = dir[k] + off * (rnd() < 0.5 ? e1[k] : e2[k]);
            tmax_lo = dist * rnd_log(0.7, 3.0);
        }
        const double al = sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
        if (!(al > 1e-6))
            continue;
        for (int k = 0; k < 3; k++)
            axis[k] /= al;
        double bgeo = rnd_log(1e-6, 0.8);
        kd_tri_view v;
        kd_dir_cone dc;
        kd_tri_view_init(&v, tri, 0, apex);
        /* a quarter of the triangles ahead: a cone touching one edge's plane
         * from either side, its tangent ray among the rays fired */
        double touch[3] = {0, 0, 0};
        if (!own && trial % 4 == 1) {
            const int e = (int)(rnd() * 3) % 3, j = (e + 1) % 3;
            double m[3], ml = 0.0, side = rnd() < 0.5 ? 1.0 : -1.0;
            for (int k = 0; k < 3; k++) { /* a point of the edge, seen from the apex */
                const double f = 0.1 + 0.8 * rnd();
                m[k] = (1 - f) * tri[3 * j + k] + f * tri[3 * ((j + 1) % 3) + k] - apex[k];
                ml += m[k] * m[k];
            }
            ml = sqrt(ml);
            bgeo = rnd_log(1e-6, 0.3);
            for (int k = 0; k < 3; k++) {
                touch[k] = m[k] / ml;
                axis[k] = cos(bgeo) * touch[k] + side * sin(bgeo) * v.edge[e][k];
            }
        }
        const double b = bgeo + 2e-7; /* the test's float directions: 1e-7 */
        kd_dir_cone_set(&dc, axis, cos(b), sin(b), tmax_lo);
        const kd_verdict vd = kd_tri_view_classify(&v, &dc);
        verdicts[vd]++;
        if (vd == KD_TRI_UNKNOWN)
            continue;
        float tmax = (float)tmax_lo;
        if ((double)tmax > tmax_lo)
            tmax = nextafterf(tmax, 0.0f);
        for (int r = 0; r < 100; r++) {
            float d[3], t = -1.0f, u, w;
            kd_ray_pre pre;
            rnd_in_cone(axis, bgeo, d);
            if (touch[0] != 0 || touch[1] != 0 || touch[2] != 0) {
                if (r < 8) /* the tangent direction and float neighbours */
                    for (int k = 0; k < 3; k++)
                        d[k] = (float)touch[k];
                if (r > 0 && r < 8)
                    d[r % 3] = nextafterf(d[r % 3], r < 4 ? INFINITY : -INFINITY);
            }
            kd_ray_precompute(apex, d, &pre);
            const int hit = kd_tri_intersect(&pre, tri, 0.0f,
                                             vd == KD_TRI_COVERS ? tmax : INFINITY, &t, &u, &w);
            rays++;
            if (hit != (vd == KD_TRI_COVERS)) {
                wrong++;
                CHECK(0, "trial %d: verdict %d but ray (%.9g %.9g %.9g) %s (t %g, tmax_lo %g)",
                      trial, (int)vd, d[0], d[1], d[2], hit ? "hits" : "misses", t,
                      tmax_lo);
                break;
            }
        }
    }
    printf("proofs: %ld unknown, %ld misses, %ld covers; %ld rays checked\n", verdicts[0],
           verdicts[1], verdicts[2], rays);
    CHECK(verdicts[1] > 5000 && verdicts[2] > 1000 && verdicts[0] > 1000,
          "the trials must reach every verdict");
}

int main(int argc, char **argv) {
    if (argc > 1) {
        fprintf(stderr, "usage: %s\n", argv[0]);
        return 2;
    }
    test_proofs();
    return check_exit("test_cone_proofs");
}
