/* Embree 3 single-ray throughput on the ray files of scripts/bench_rays.py.
 *
 * A development tool, never a dependency of Penumbra: compiled by
 * scripts/bench_rays.py with
 *   gcc -O2 -o bench bench.c -lembree3 -lpthread
 * against Debian's libembree-dev (Embree 3; `apt-get install -y libembree-dev`).
 *
 * Usage: bench DIR KIND QUERY THREADS REPS [robust]
 *   DIR/mesh.bin           u32 shapes; per shape: u32 nv, u32 nf,
 *                          f32 positions[nv][3], u32 faces[nf][3]
 *                          (world space; one Embree geometry per shape, so
 *                          geomID = Penumbra's shape index)
 *   DIR/rays_KIND.bin      f32 [n][8]: origin, direction, tmin, tmax
 *   QUERY                  closest (rtcIntersect1) or occluded (rtcOccluded1)
 *   THREADS                rays split in chunks of CHUNK rays, handed out
 *                          by an atomic counter to THREADS pthreads
 *   REPS                   traces of all the rays, each timed, after one
 *                          untimed (warm-up)
 *   robust                 RTC_SCENE_FLAG_ROBUST (default: no scene flags)
 * With PACKET=16 in the environment, each 16 consecutive rays are traced as
 * one packet (rtcIntersect16 / rtcOccluded16: Embree's hybrid traversal,
 * packets while their rays agree and single rays after, as Mitsuba's
 * llvm variants call it 16 lanes wide).
 * The build uses Embree's default quality (RTC_BUILD_QUALITY_MEDIUM) and
 * THREADS build threads; it is timed apart. Writes the hits of the last
 * trace to DIR/embree_KIND_tTHREADS.bin (closest: per ray f32 t, inf on a
 * miss, i32 geomID, i32 primID, -1 on a miss; occluded: u8 per ray) and
 * prints one line: RESULT {json}.
 */
#define _POSIX_C_SOURCE 200809L /* clock_gettime under -std=c11 */
#include <embree3/rtcore.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define CHUNK 1024

static void die(const char *what) {
    fprintf(stderr, "embree_bench: %s\n", what);
    exit(1);
}

static void *read_file(const char *path, size_t *size) {
    FILE *f = fopen(path, "rb");
    if (!f) die(path);
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    void *buf = malloc(n > 0 ? (size_t)n : 1);
    if (!buf || fread(buf, 1, (size_t)n, f) != (size_t)n) die(path);
    fclose(f);
    *size = (size_t)n;
    return buf;
}

static void on_error(void *user, enum RTCError code, const char *msg) {
    (void)user;
    fprintf(stderr, "embree error %d: %s\n", (int)code, msg);
    exit(1);
}

struct job {
    RTCScene scene;
    const float *rays; /* [n][8] */
    size_t n;
    int occluded;
    int packets; /* PACKET=16: rays 16 at a time */
    atomic_size_t next;
    float *t;
    int32_t *geom, *prim;
    uint8_t *hit;
};

/* rays [start, end) in packets of 16 (the last one partly valid) */
static void trace16(struct job *j, struct RTCIntersectContext *ctx, size_t start, size_t end) {
    for (size_t i0 = start; i0 < end; i0 += 16) {
        int valid[16];
        struct RTCRayHit16 h;
        memset(&h, 0, sizeof h);
        for (int k = 0; k < 16; k++) {
            valid[k] = i0 + k < end ? -1 : 0;
            const float *r = j->rays + 8 * (valid[k] ? i0 + k : start);
            h.ray.org_x[k] = r[0], h.ray.org_y[k] = r[1], h.ray.org_z[k] = r[2];
            h.ray.dir_x[k] = r[3], h.ray.dir_y[k] = r[4], h.ray.dir_z[k] = r[5];
            h.ray.tnear[k] = r[6], h.ray.tfar[k] = r[7];
            h.ray.mask[k] = 0xffffffffu;
            h.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
            h.hit.instID[0][k] = RTC_INVALID_GEOMETRY_ID;
        }
        if (j->occluded) rtcOccluded16(valid, j->scene, ctx, &h.ray);
        else rtcIntersect16(valid, j->scene, ctx, &h);
        for (int k = 0; k < 16 && i0 + k < end; k++) {
            size_t i = i0 + k;
            if (j->occluded) {
                j->hit[i] = h.ray.tfar[k] < 0.0f;
                continue;
            }
            int miss = h.hit.geomID[k] == RTC_INVALID_GEOMETRY_ID;
            j->t[i] = miss ? INFINITY : h.ray.tfar[k];
            j->geom[i] = miss ? -1 : (int32_t)h.hit.geomID[k];
            j->prim[i] = miss ? -1 : (int32_t)h.hit.primID[k];
        }
    }
}

static void *worker(void *arg) {
    struct job *j = arg;
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (;;) {
        size_t start = atomic_fetch_add(&j->next, CHUNK);
        if (start >= j->n) break;
        size_t end = start + CHUNK < j->n ? start + CHUNK : j->n;
        if (j->packets) {
            trace16(j, &ctx, start, end);
            continue;
        }
        for (size_t i = start; i < end; i++) {
            const float *r = j->rays + 8 * i;
            if (j->occluded) {
                struct RTCRay ray = {
                    .org_x = r[0], .org_y = r[1], .org_z = r[2], .tnear = r[6],
                    .dir_x = r[3], .dir_y = r[4], .dir_z = r[5], .time = 0.0f,
                    .tfar = r[7], .mask = 0xffffffffu, .id = 0, .flags = 0};
                rtcOccluded1(j->scene, &ctx, &ray);
                j->hit[i] = ray.tfar < 0.0f;
            } else {
                struct RTCRayHit rh;
                memset(&rh, 0, sizeof rh);
                rh.ray.org_x = r[0], rh.ray.org_y = r[1], rh.ray.org_z = r[2];
                rh.ray.dir_x = r[3], rh.ray.dir_y = r[4], rh.ray.dir_z = r[5];
                rh.ray.tnear = r[6], rh.ray.tfar = r[7];
                rh.ray.mask = 0xffffffffu;
                rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
                rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
                rtcIntersect1(j->scene, &ctx, &rh);
                int miss = rh.hit.geomID == RTC_INVALID_GEOMETRY_ID;
                j->t[i] = miss ? INFINITY : rh.ray.tfar;
                j->geom[i] = miss ? -1 : (int32_t)rh.hit.geomID;
                j->prim[i] = miss ? -1 : (int32_t)rh.hit.primID;
            }
        }
    }
    return NULL;
}

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

int main(int argc, char **argv) {
    if (argc < 6) die("usage: bench DIR KIND QUERY THREADS REPS [robust]");
    const char *dir = argv[1], *kind = argv[2];
    int occluded = strcmp(argv[3], "occluded") == 0;
    if (!occluded && strcmp(argv[3], "closest") != 0) die("QUERY is closest or occluded");
    int threads = atoi(argv[4]), reps = atoi(argv[5]);
    int robust = argc > 6 && strcmp(argv[6], "robust") == 0;
    if (threads < 1 || reps < 1) die("THREADS and REPS must be >= 1");
    char path[4096], config[64];

    snprintf(config, sizeof config, "threads=%d", threads);
    RTCDevice dev = rtcNewDevice(config);
    if (!dev) die("rtcNewDevice failed");
    rtcSetDeviceErrorFunction(dev, on_error, NULL);

    size_t size;
    snprintf(path, sizeof path, "%s/mesh.bin", dir);
    uint8_t *mesh = read_file(path, &size), *p = mesh;
    double t0 = now();
    RTCScene scene = rtcNewScene(dev);
    if (robust) rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
    uint32_t shapes, tris = 0;
    memcpy(&shapes, p, 4), p += 4;
    for (uint32_t s = 0; s < shapes; s++) {
        uint32_t nv, nf;
        memcpy(&nv, p, 4), memcpy(&nf, p + 4, 4), p += 8;
        RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
        /* Embree's own buffers: padded as its SIMD loads need */
        void *v = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                          12, nv);
        memcpy(v, p, 12 * (size_t)nv), p += 12 * (size_t)nv;
        void *f = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                          12, nf);
        memcpy(f, p, 12 * (size_t)nf), p += 12 * (size_t)nf;
        rtcCommitGeometry(g);
        if (rtcAttachGeometry(scene, g) != s) die("unexpected geomID");
        rtcReleaseGeometry(g);
        tris += nf;
    }
    if ((size_t)(p - mesh) != size) die("mesh.bin: size does not match its counts");
    rtcCommitScene(scene);
    double build = now() - t0;

    snprintf(path, sizeof path, "%s/rays_%s.bin", dir, kind);
    float *rays = read_file(path, &size);
    struct job j = {.scene = scene, .rays = rays, .n = size / 32, .occluded = occluded};
    const char *packet = getenv("PACKET");
    j.packets = packet && strcmp(packet, "16") == 0;
    if (packet && !j.packets) die("PACKET: only 16 is supported");
    j.t = malloc(4 * j.n + 1), j.geom = malloc(4 * j.n + 1), j.prim = malloc(4 * j.n + 1);
    j.hit = malloc(j.n + 1);
    pthread_t *th = malloc(sizeof(pthread_t) * threads);
    printf("RESULT {\"side\": \"embree\", \"kind\": \"%s\", \"threads\": %d, \"rays\": %zu, "
           "\"triangles\": %u, \"build_s\": %.6f, \"times\": [",
           kind, threads, j.n, tris, build);
    for (int r = -1; r < reps; r++) { /* r = -1: a warm-up trace, not timed */
        atomic_store(&j.next, 0);
        double s = now();
        for (int k = 1; k < threads; k++)
            if (pthread_create(&th[k], NULL, worker, &j)) die("pthread_create");
        worker(&j); /* the calling thread is one of the THREADS */
        for (int k = 1; k < threads; k++) pthread_join(th[k], NULL);
        if (r >= 0) printf("%s%.6f", r ? ", " : "", now() - s);
    }
    printf("], \"embree\": \"%s\", \"robust\": %s, \"packet\": %d}\n", RTC_VERSION_STRING,
           robust ? "true" : "false", j.packets ? 16 : 1);

    snprintf(path, sizeof path, "%s/embree_%s_t%d.bin", dir, kind, threads);
    FILE *out = fopen(path, "wb");
    if (!out) die(path);
    if (occluded) {
        fwrite(j.hit, 1, j.n, out);
    } else {
        for (size_t i = 0; i < j.n; i++) {
            fwrite(&j.t[i], 4, 1, out);
            fwrite(&j.geom[i], 4, 1, out);
            fwrite(&j.prim[i], 4, 1, out);
        }
    }
    fclose(out);
    rtcReleaseScene(scene);
    rtcReleaseDevice(dev);
    return 0;
}
