/* A stand-in for libOrbbecSDK.so (Orbbec SDK v2 C API, 2.9.x signatures) for the tests that run
 * the `hitl` binary with an Orbbec camera (`HITL_ORBBEC_LIB` pointing at this library): every
 * symbol the driver resolves, with just enough behaviour for it.
 *
 * Everything lives in the folder named by $HITL_FAKE_ORBBEC_DIR, so a test can set the cameras
 * up before the process starts and look at them after it ended (as a camera keeps its
 * configuration across processes):
 *   cameras          one line per connected camera: SERIAL PID(hex) FIRMWARE NAME...
 *   SERIAL.sync      the camera's sync configuration: mode depth colour trigger2image out
 *                    out_delay frames (ints; created as the factory's: free-run, trigger out on)
 *   SERIAL.props     exposure reference and sync voltage level (ints)
 *   sizes            (optional) one "WIDTH HEIGHT" a line: the sizes every stream offers
 *                    (default 1280x800, 640x400, 64x40)
 *   log              one line per call that changes something (sync, prop, start, stop, trigger)
 *   pulses           (optional FIFO) each 8 bytes written are one pulse on the sync input, the
 *                    pulse's time on CLOCK_MONOTONIC in microseconds (little-endian): the camera
 *                    sends one frameset per pulse, exposed then (a software trigger sends one
 *                    too, exposed at the trigger)
 * The sync voltage property (270) exists from firmware 1.0.76 on, as on the Gemini 305.
 * Frames: RGB colour of grey 128 and Y16 depth of 1500 units (1 mm each: 1.5 m), the system
 * (arrival) timestamp when the driver takes the frameset, the global (exposure) timestamp the
 * pulse's or the software trigger's time, both on CLOCK_MONOTONIC. */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

typedef struct {
    int status;
    int exception;
    char message[256];
    char function[64];
} ob_error;

#pragma pack(push, 1)
typedef struct {
    int sync_mode;
    int depth_delay_us;
    int color_delay_us;
    int trigger_to_image_delay_us;
    bool trigger_out_enable;
    int trigger_out_delay_us;
    int frames_per_trigger;
} ob_multi_device_sync_config;
#pragma pack(pop)

typedef struct {
    float fx, fy, cx, cy;
    int16_t width, height;
} ob_camera_intrinsic;

typedef struct {
    float k[6];
    float p1, p2;
    int model;
} ob_camera_distortion;

typedef struct {
    float rot[9];
    float trans[3];
} ob_extrinsic;

#define MAX_CAMS 8
typedef struct {
    char serial[64];
    int pid;
    char firmware[32];
    char name[128];
} camera;

static camera cams[MAX_CAMS];
static int ncams = -1;

typedef struct { int dummy; } ob_context;
typedef struct { int count; } ob_device_list;
typedef struct {
    int cam;
    bool global;
} ob_device;
typedef struct { int cam; } ob_device_info;

typedef struct {
    int sensor;
    int format;
    uint32_t width, height, fps;
} ob_stream_profile;

typedef struct {
    int count;
    ob_stream_profile items[32];
} ob_stream_profile_list;

typedef struct {
    ob_stream_profile color, depth;
    bool has_color, has_depth;
} ob_config;

typedef struct {
    int cam;
    bool started;
    ob_stream_profile color, depth;
    int fifo;
    uint8_t partial[8];
    int partial_len;
} ob_pipeline;

typedef struct ob_frame {
    int refs;
    int kind; /* 0 frameset, 2 colour, 3 depth */
    int format;
    uint32_t width, height;
    uint8_t *data;
    uint32_t size;
    uint64_t device_us, system_us, global_us;
    float scale;
    struct ob_frame *color, *depth;
} ob_frame;

typedef struct { int dummy; } ob_filter;

static ob_device *devices_open[MAX_CAMS];
/* Exposure times (us) of the triggers each camera took and has not answered with a frameset. */
#define MAX_PENDING 256
typedef struct {
    uint64_t at[MAX_PENDING];
    int head, count;
} stamps;
static stamps pending[MAX_CAMS];

static void push_stamp(int cam, uint64_t us) {
    stamps *q = &pending[cam];
    if (q->count == MAX_PENDING) return;
    q->at[(q->head + q->count) % MAX_PENDING] = us;
    q->count++;
}

static bool pop_stamp(int cam, uint64_t *us) {
    stamps *q = &pending[cam];
    if (q->count == 0) return false;
    *us = q->at[q->head];
    q->head = (q->head + 1) % MAX_PENDING;
    q->count--;
    return true;
}

static const char *dir(void) {
    const char *d = getenv("HITL_FAKE_ORBBEC_DIR");
    return (d && *d) ? d : NULL;
}

static void set_error(ob_error **error, int exception, const char *function, const char *fmt, ...) {
    if (!error) return;
    ob_error *e = calloc(1, sizeof *e);
    e->status = 1;
    e->exception = exception;
    snprintf(e->function, sizeof e->function, "%s", function);
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(e->message, sizeof e->message, fmt, ap);
    va_end(ap);
    *error = e;
}

static void logline(const char *fmt, ...) {
    if (!dir()) return;
    char path[512];
    snprintf(path, sizeof path, "%s/log", dir());
    FILE *f = fopen(path, "a");
    if (!f) return;
    va_list ap;
    va_start(ap, fmt);
    vfprintf(f, fmt, ap);
    va_end(ap);
    fputc('\n', f);
    fclose(f);
}

static void load_cameras(void) {
    if (ncams >= 0) return;
    ncams = 0;
    if (!dir()) return;
    char path[512];
    snprintf(path, sizeof path, "%s/cameras", dir());
    FILE *f = fopen(path, "r");
    if (!f) return;
    char line[512];
    while (ncams < MAX_CAMS && fgets(line, sizeof line, f)) {
        camera *c = &cams[ncams];
        int used = 0;
        if (sscanf(line, "%63s %x %31s %n", c->serial, &c->pid, c->firmware, &used) < 3) continue;
        snprintf(c->name, sizeof c->name, "%s", line + used);
        c->name[strcspn(c->name, "\n")] = 0;
        ncams++;
    }
    fclose(f);
}

static bool has_voltage(int cam) {
    int a = 0, b = 0, c = 0;
    if (sscanf(cams[cam].firmware, "%d.%d.%d", &a, &b, &c) != 3) return false;
    return a > 1 || (a == 1 && (b > 0 || c >= 76));
}

static ob_multi_device_sync_config read_sync(int cam) {
    ob_multi_device_sync_config s = {1, 0, 0, 0, true, 0, 1}; /* free-run, trigger out on */
    char path[512];
    snprintf(path, sizeof path, "%s/%s.sync", dir(), cams[cam].serial);
    FILE *f = fopen(path, "r");
    if (f) {
        int v[7];
        if (fscanf(f, "%d %d %d %d %d %d %d", &v[0], &v[1], &v[2], &v[3], &v[4], &v[5], &v[6]) == 7) {
            s.sync_mode = v[0];
            s.depth_delay_us = v[1];
            s.color_delay_us = v[2];
            s.trigger_to_image_delay_us = v[3];
            s.trigger_out_enable = v[4] != 0;
            s.trigger_out_delay_us = v[5];
            s.frames_per_trigger = v[6];
        }
        fclose(f);
    }
    return s;
}

static void write_sync(int cam, const ob_multi_device_sync_config *s) {
    char path[512];
    snprintf(path, sizeof path, "%s/%s.sync", dir(), cams[cam].serial);
    FILE *f = fopen(path, "w");
    if (!f) return;
    fprintf(f, "%d %d %d %d %d %d %d\n", s->sync_mode, s->depth_delay_us, s->color_delay_us,
            s->trigger_to_image_delay_us, s->trigger_out_enable ? 1 : 0, s->trigger_out_delay_us,
            s->frames_per_trigger);
    fclose(f);
}

static void read_props(int cam, int *ref, int *volt) {
    *ref = 0;
    *volt = 0;
    char path[512];
    snprintf(path, sizeof path, "%s/%s.props", dir(), cams[cam].serial);
    FILE *f = fopen(path, "r");
    if (!f) return;
    if (fscanf(f, "%d %d", ref, volt) != 2) {
        *ref = 0;
        *volt = 0;
    }
    fclose(f);
}

static void write_props(int cam, int ref, int volt) {
    char path[512];
    snprintf(path, sizeof path, "%s/%s.props", dir(), cams[cam].serial);
    FILE *f = fopen(path, "w");
    if (!f) return;
    fprintf(f, "%d %d\n", ref, volt);
    fclose(f);
}

static uint64_t now_us(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (uint64_t)t.tv_sec * 1000000u + (uint64_t)t.tv_nsec / 1000u;
}

/* ---- versions, errors, logging ---- */
int ob_get_major_version(void) { return 2; }
int ob_get_minor_version(void) { return 9; }
int ob_get_patch_version(void) { return 3; }
int ob_error_get_status(const ob_error *e) { return e->status; }
const char *ob_error_get_message(const ob_error *e) { return e->message; }
const char *ob_error_get_function(const ob_error *e) { return e->function; }
int ob_error_get_exception_type(const ob_error *e) { return e->exception; }
void ob_delete_error(ob_error *e) { free(e); }
void ob_set_logger_to_file(int s, const char *d, ob_error **e) { (void)s; (void)d; (void)e; }
void ob_set_logger_to_console(int s, ob_error **e) { (void)s; (void)e; }

/* ---- context and devices ---- */
ob_context *ob_create_context(ob_error **e) {
    (void)e;
    load_cameras();
    return calloc(1, sizeof(ob_context));
}
void ob_delete_context(ob_context *c, ob_error **e) { (void)e; free(c); }
void ob_context_set_timestamp_clock_type(ob_context *c, int t, ob_error **e) { (void)c; (void)t; (void)e; }
ob_device_list *ob_query_device_list(ob_context *c, ob_error **e) {
    (void)c; (void)e;
    ob_device_list *l = calloc(1, sizeof *l);
    l->count = ncams;
    return l;
}
void ob_delete_device_list(ob_device_list *l, ob_error **e) { (void)e; free(l); }
uint32_t ob_device_list_get_count(const ob_device_list *l, ob_error **e) { (void)e; return (uint32_t)l->count; }
const char *ob_device_list_get_device_serial_number(const ob_device_list *l, uint32_t i, ob_error **e) {
    if ((int)i >= l->count) {
        set_error(e, 4, __func__, "index %u out of range", i);
        return NULL;
    }
    return cams[i].serial;
}
ob_device *ob_device_list_get_device(const ob_device_list *l, uint32_t i, ob_error **e) {
    if ((int)i >= l->count) {
        set_error(e, 4, __func__, "index %u out of range", i);
        return NULL;
    }
    ob_device *d = calloc(1, sizeof *d);
    d->cam = (int)i;
    devices_open[i] = d;
    logline("open %s", cams[i].serial);
    return d;
}
void ob_delete_device(ob_device *d, ob_error **e) {
    (void)e;
    if (d && devices_open[d->cam] == d) devices_open[d->cam] = NULL;
    free(d);
}
ob_device_info *ob_device_get_device_info(const ob_device *d, ob_error **e) {
    (void)e;
    ob_device_info *i = calloc(1, sizeof *i);
    i->cam = d->cam;
    return i;
}
void ob_delete_device_info(ob_device_info *i, ob_error **e) { (void)e; free(i); }
const char *ob_device_info_get_name(const ob_device_info *i, ob_error **e) { (void)e; return cams[i->cam].name; }
const char *ob_device_info_get_serial_number(const ob_device_info *i, ob_error **e) { (void)e; return cams[i->cam].serial; }
int ob_device_info_get_pid(const ob_device_info *i, ob_error **e) { (void)e; return cams[i->cam].pid; }
const char *ob_device_info_get_firmware_version(const ob_device_info *i, ob_error **e) { (void)e; return cams[i->cam].firmware; }

/* ---- properties and sync ---- */
bool ob_device_is_property_supported(const ob_device *d, int id, int perm, ob_error **e) {
    (void)perm; (void)e;
    if (id == 236) return true;
    if (id == 270) return has_voltage(d->cam);
    return false;
}
void ob_device_set_int_property(ob_device *d, int id, int32_t v, ob_error **e) {
    int ref, volt;
    read_props(d->cam, &ref, &volt);
    if (id == 236) ref = v;
    else if (id == 270 && has_voltage(d->cam)) volt = v;
    else {
        set_error(e, 9, __func__, "property %d not supported", id);
        return;
    }
    write_props(d->cam, ref, volt);
    logline("prop %s %d %d", cams[d->cam].serial, id, v);
}
int32_t ob_device_get_int_property(ob_device *d, int id, ob_error **e) {
    int ref, volt;
    read_props(d->cam, &ref, &volt);
    if (id == 236) return ref;
    if (id == 270 && has_voltage(d->cam)) return volt;
    set_error(e, 9, __func__, "property %d not supported", id);
    return 0;
}
uint16_t ob_device_get_supported_multi_device_sync_mode_bitmap(const ob_device *d, ob_error **e) {
    (void)d; (void)e;
    return 0x7F;
}
ob_multi_device_sync_config ob_device_get_multi_device_sync_config(const ob_device *d, ob_error **e) {
    (void)e;
    return read_sync(d->cam);
}
void ob_device_set_multi_device_sync_config(ob_device *d, const ob_multi_device_sync_config *s, ob_error **e) {
    (void)e;
    write_sync(d->cam, s);
    logline("sync %s %d out %d", cams[d->cam].serial, s->sync_mode, s->trigger_out_enable ? 1 : 0);
}
bool ob_device_is_global_timestamp_supported(const ob_device *d, ob_error **e) { (void)d; (void)e; return true; }
void ob_device_enable_global_timestamp(ob_device *d, bool on, ob_error **e) { (void)e; d->global = on; }

/* ---- profiles ---- */
static uint32_t SIZES[8][2] = {{1280, 800}, {640, 400}, {64, 40}};
static int nsizes = 3;

static void load_sizes(void) {
    char path[512];
    snprintf(path, sizeof path, "%s/sizes", dir());
    FILE *f = fopen(path, "r");
    if (!f) return;
    unsigned w, h;
    int n = 0;
    while (n < 8 && fscanf(f, "%u %u", &w, &h) == 2) {
        SIZES[n][0] = w;
        SIZES[n][1] = h;
        n++;
    }
    if (n > 0) nsizes = n;
    fclose(f);
}

ob_pipeline *ob_create_pipeline_with_device(const ob_device *d, ob_error **e) {
    (void)e;
    ob_pipeline *p = calloc(1, sizeof *p);
    p->cam = d->cam;
    p->fifo = -1;
    return p;
}
void ob_delete_pipeline(ob_pipeline *p, ob_error **e) {
    (void)e;
    if (p->fifo >= 0) close(p->fifo);
    free(p);
}
ob_stream_profile_list *ob_pipeline_get_stream_profile_list(const ob_pipeline *p, int sensor, ob_error **e) {
    (void)p; (void)e;
    ob_stream_profile_list *l = calloc(1, sizeof *l);
    load_sizes();
    for (int s = 0; s < nsizes; s++) {
        for (int f = 0; f < 2; f++) {
            ob_stream_profile *x = &l->items[l->count++];
            x->sensor = sensor;
            x->format = sensor == 2 ? 22 : 8; /* RGB, Y16 */
            x->width = SIZES[s][0];
            x->height = SIZES[s][1];
            x->fps = f == 0 ? 30 : 15;
        }
    }
    if (sensor == 2) { /* an MJPG colour profile too */
        ob_stream_profile *x = &l->items[l->count++];
        *x = l->items[0];
        x->format = 5;
    }
    return l;
}
void ob_delete_stream_profile_list(const ob_stream_profile_list *l, ob_error **e) { (void)e; free((void *)l); }
uint32_t ob_stream_profile_list_get_count(const ob_stream_profile_list *l, ob_error **e) { (void)e; return (uint32_t)l->count; }
ob_stream_profile *ob_stream_profile_list_get_profile(const ob_stream_profile_list *l, int i, ob_error **e) {
    if (i < 0 || i >= l->count) {
        set_error(e, 4, __func__, "index out of range");
        return NULL;
    }
    ob_stream_profile *p = malloc(sizeof *p);
    *p = l->items[i];
    return p;
}
ob_stream_profile *ob_stream_profile_list_get_video_stream_profile(const ob_stream_profile_list *l, int w, int h, int fmt, int fps, ob_error **e) {
    for (int i = 0; i < l->count; i++) {
        const ob_stream_profile *x = &l->items[i];
        if ((w == 0 || (uint32_t)w == x->width) && (h == 0 || (uint32_t)h == x->height) &&
            (fmt < 0 || fmt == x->format) && (fps == 0 || (uint32_t)fps == x->fps)) {
            ob_stream_profile *p = malloc(sizeof *p);
            *p = *x;
            return p;
        }
    }
    set_error(e, 4, __func__, "no matching profile %dx%d format %d @%d", w, h, fmt, fps);
    return NULL;
}
int ob_stream_profile_get_format(const ob_stream_profile *p, ob_error **e) { (void)e; return p->format; }
uint32_t ob_video_stream_profile_get_fps(const ob_stream_profile *p, ob_error **e) { (void)e; return p->fps; }
void ob_delete_stream_profile(const ob_stream_profile *p, ob_error **e) { (void)e; free((void *)p); }
ob_camera_intrinsic ob_video_stream_profile_get_intrinsic(const ob_stream_profile *p, ob_error **e) {
    (void)e;
    ob_camera_intrinsic k = {0.75f * (float)p->width, 0.75f * (float)p->width, (float)p->width / 2.0f,
                             (float)p->height / 2.0f, (int16_t)p->width, (int16_t)p->height};
    return k;
}
ob_camera_distortion ob_video_stream_profile_get_distortion(const ob_stream_profile *p, ob_error **e) {
    (void)e;
    ob_camera_distortion d = {{0}, 0, 0, 0};
    if (p->sensor == 2) {
        d.k[0] = 0.125f;
        d.k[1] = -0.25f;
        d.p1 = 0.001f;
        d.p2 = -0.002f;
        d.model = 3; /* Brown-Conrady */
    }
    return d;
}
uint32_t ob_video_stream_profile_get_width(const ob_stream_profile *p, ob_error **e) { (void)e; return p->width; }
uint32_t ob_video_stream_profile_get_height(const ob_stream_profile *p, ob_error **e) { (void)e; return p->height; }

/* ---- streaming ---- */
ob_config *ob_create_config(ob_error **e) { (void)e; return calloc(1, sizeof(ob_config)); }
void ob_delete_config(ob_config *c, ob_error **e) { (void)e; free(c); }
void ob_config_enable_stream_with_stream_profile(ob_config *c, const ob_stream_profile *p, ob_error **e) {
    (void)e;
    if (p->sensor == 2) {
        c->color = *p;
        c->has_color = true;
    } else {
        c->depth = *p;
        c->has_depth = true;
    }
}
void ob_config_set_frame_aggregate_output_mode(ob_config *c, int m, ob_error **e) { (void)c; (void)m; (void)e; }
void ob_pipeline_start_with_config(ob_pipeline *p, const ob_config *c, ob_error **e) {
    if (!c->has_color || !c->has_depth) {
        set_error(e, 4, __func__, "both streams needed");
        return;
    }
    p->color = c->color;
    p->depth = c->depth;
    p->started = true;
    pending[p->cam].count = 0;
    char path[512];
    snprintf(path, sizeof path, "%s/pulses", dir());
    if (p->fifo < 0) p->fifo = open(path, O_RDWR | O_NONBLOCK);
    logline("start %s %ux%u", cams[p->cam].serial, c->color.width, c->color.height);
}
void ob_pipeline_stop(ob_pipeline *p, ob_error **e) {
    (void)e;
    p->started = false;
    logline("stop %s", cams[p->cam].serial);
}
void ob_device_trigger_capture(ob_device *d, ob_error **e) {
    (void)e;
    logline("trigger %s", cams[d->cam].serial);
    push_stamp(d->cam, now_us());
}

static ob_frame *new_frame(int kind, int format, uint32_t w, uint32_t h, uint32_t bpp) {
    ob_frame *f = calloc(1, sizeof *f);
    f->refs = 1;
    f->kind = kind;
    f->format = format;
    f->width = w;
    f->height = h;
    f->size = w * h * bpp;
    f->data = malloc(f->size ? f->size : 1);
    return f;
}

ob_frame *ob_pipeline_wait_for_frameset(ob_pipeline *p, uint32_t timeout_ms, ob_error **e) {
    (void)e;
    if (!p->started) return NULL;
    if (pending[p->cam].count == 0 && p->fifo >= 0) {
        struct pollfd pfd = {p->fifo, POLLIN, 0};
        if (poll(&pfd, 1, (int)timeout_ms) > 0) {
            uint8_t buf[256];
            ssize_t n = read(p->fifo, buf, sizeof buf);
            for (ssize_t i = 0; i < n; i++) {
                p->partial[p->partial_len++] = buf[i];
                if (p->partial_len == 8) {
                    uint64_t us = 0;
                    for (int b = 7; b >= 0; b--) us = (us << 8) | p->partial[b];
                    push_stamp(p->cam, us);
                    p->partial_len = 0;
                }
            }
        }
    } else if (pending[p->cam].count == 0) {
        usleep(timeout_ms * 1000u);
    }
    uint64_t exposed = 0;
    if (!pop_stamp(p->cam, &exposed)) return NULL;
    uint64_t now = now_us();
    bool global = devices_open[p->cam] && devices_open[p->cam]->global;
    ob_frame *c = new_frame(2, 22, p->color.width, p->color.height, 3);
    memset(c->data, 128, c->size);
    ob_frame *d = new_frame(3, 8, p->color.width, p->color.height, 2);
    for (uint32_t i = 0; i < d->size / 2; i++) {
        d->data[2 * i] = 1500 & 0xFF;
        d->data[2 * i + 1] = 1500 >> 8;
    }
    d->scale = 1.0f;
    ob_frame *fs[2] = {c, d};
    for (int i = 0; i < 2; i++) {
        fs[i]->device_us = now;
        fs[i]->system_us = now;
        fs[i]->global_us = global ? exposed : 0;
    }
    ob_frame *set = new_frame(0, 0, 0, 0, 0);
    set->color = c;
    set->depth = d;
    return set;
}
ob_frame *ob_frameset_get_color_frame(const ob_frame *s, ob_error **e) {
    (void)e;
    if (!s->color) return NULL;
    s->color->refs++;
    return s->color;
}
ob_frame *ob_frameset_get_depth_frame(const ob_frame *s, ob_error **e) {
    (void)e;
    if (!s->depth) return NULL;
    s->depth->refs++;
    return s->depth;
}
void ob_delete_frame(const ob_frame *cf, ob_error **e) {
    ob_frame *f = (ob_frame *)cf;
    if (!f || --f->refs > 0) return;
    if (f->color) ob_delete_frame(f->color, e);
    if (f->depth) ob_delete_frame(f->depth, e);
    free(f->data);
    free(f);
}
int ob_frame_get_format(const ob_frame *f, ob_error **e) { (void)e; return f->format; }
uint8_t *ob_frame_get_data(const ob_frame *f, ob_error **e) { (void)e; return f->data; }
uint32_t ob_frame_get_data_size(const ob_frame *f, ob_error **e) { (void)e; return f->size; }
uint64_t ob_frame_get_timestamp_us(const ob_frame *f, ob_error **e) { (void)e; return f->device_us; }
uint64_t ob_frame_get_system_timestamp_us(const ob_frame *f, ob_error **e) { (void)e; return f->system_us; }
uint64_t ob_frame_get_global_timestamp_us(const ob_frame *f, ob_error **e) { (void)e; return f->global_us; }
uint32_t ob_video_frame_get_width(const ob_frame *f, ob_error **e) { (void)e; return f->width; }
uint32_t ob_video_frame_get_height(const ob_frame *f, ob_error **e) { (void)e; return f->height; }
float ob_depth_frame_get_value_scale(const ob_frame *f, ob_error **e) { (void)e; return f->scale; }

/* ---- the Align filter: the fake's depth already has the colour's size ---- */
ob_filter *ob_create_filter(const char *name, ob_error **e) {
    if (strcmp(name, "Align") != 0) {
        set_error(e, 13, __func__, "no filter %s", name);
        return NULL;
    }
    return calloc(1, sizeof(ob_filter));
}
void ob_delete_filter(ob_filter *f, ob_error **e) { (void)e; free(f); }
void ob_filter_set_config_value(ob_filter *f, const char *k, double v, ob_error **e) { (void)f; (void)k; (void)v; (void)e; }
ob_frame *ob_filter_process(ob_filter *f, const ob_frame *s, ob_error **e) {
    (void)f; (void)e;
    ((ob_frame *)s)->refs++;
    return (ob_frame *)s;
}

/* ---- frame builders (only the driver's tests against the real library call these) ---- */
#define UNSUPPORTED(ret, name, ...)                                     \
    ret name(__VA_ARGS__, ob_error **e) {                              \
        set_error(e, 9, #name, "not offered by the fake Orbbec SDK");  \
        return (ret)0;                                                 \
    }
#define UNSUPPORTED_VOID(name, ...)                                    \
    void name(__VA_ARGS__, ob_error **e) {                             \
        set_error(e, 9, #name, "not offered by the fake Orbbec SDK");  \
    }
UNSUPPORTED(ob_stream_profile *, ob_create_video_stream_profile, int a, int b, uint32_t c, uint32_t d, uint32_t f)
UNSUPPORTED_VOID(ob_video_stream_profile_set_intrinsic, ob_stream_profile *p, ob_camera_intrinsic k)
UNSUPPORTED_VOID(ob_video_stream_profile_set_distortion, ob_stream_profile *p, ob_camera_distortion d)
UNSUPPORTED_VOID(ob_stream_profile_set_extrinsic_to, ob_stream_profile *p, const ob_stream_profile *q, ob_extrinsic x)
UNSUPPORTED(ob_frame *, ob_create_video_frame, int a, int b, uint32_t c, uint32_t d, uint32_t f)
UNSUPPORTED_VOID(ob_frame_set_stream_profile, ob_frame *f, const ob_stream_profile *p)
UNSUPPORTED_VOID(ob_frame_update_data, ob_frame *f, const uint8_t *d, uint32_t n)
UNSUPPORTED_VOID(ob_frame_set_timestamp_us, ob_frame *f, uint64_t t)
UNSUPPORTED_VOID(ob_frame_set_system_timestamp_us, ob_frame *f, uint64_t t)
UNSUPPORTED_VOID(ob_depth_frame_set_value_scale, ob_frame *f, float s)
UNSUPPORTED_VOID(ob_frameset_push_frame, ob_frame *s, const ob_frame *f)
ob_frame *ob_create_frameset(ob_error **e) {
    set_error(e, 9, __func__, "not offered by the fake Orbbec SDK");
    return NULL;
}
