/* replay.c: a recorded run through the rbf-core C library, as a C firmware
 * would run it, written as `trainer compensate` writes it (after its
 * provenance lines, which `cargo xtask c-replay` adds): byte for byte.
 *
 *   replay MODEL.bin SAMPLE_RATE_HZ RUN.csv OUT.csv
 *
 * The same source runs on the host (cc) and on the STM32F405 under QEMU
 * (arm-none-eabi-gcc, newlib; files over semihosting). A run with `rate_dph`
 * goes through rbf_gyro_*, one with `rate_x_dph` ... through rbf_imu_*. The
 * thermometers are read as the board's TMP117s report them (1/128 degC).
 * Its last line: rows, the model's CRC-32, axes and provenance id (or
 * `provenance none`). A refused blob: the library's status in words, exit 2. Exit 1: a file
 * that cannot be read or written, or a line this reader does not take
 * (`cargo xtask c-replay` runs trainer compensate's checks first). */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "rbf_core.h"

#define MAX_LINE (64 * 1024)
#define MAX_FIELDS 1024
#define MAX_BLOB (8 * 1024)

static _Alignas(RBF_GYRO_STATE_ALIGN) uint8_t gyro_state[RBF_GYRO_STATE_SIZE];
static _Alignas(RBF_IMU_STATE_ALIGN) uint8_t imu_state[RBF_IMU_STATE_SIZE];
static uint8_t blob[MAX_BLOB];
static char line[MAX_LINE + 2];
static char values[RBF_AXES * 64];
static const char *fields[MAX_FIELDS];
static size_t field_count;

static const char *const AXIS_NAMES[RBF_AXES] = {"x", "y", "z"};

/* Where the known columns are (-1: absent). */
struct columns {
    int time_s, rate_dph, temp_fault;
    int temps[RBF_THERMOMETERS];
    int axis_rate[RBF_AXES], axis_temp[RBF_AXES];
    int multi_axis;
};

static void fail(const char *what, const char *why) {
    fprintf(stderr, "%s: %s\n", what, why);
    exit(1);
}

/* Spaces, tabs and carriage returns, as the recorded-run reader trims. */
static int blank(char c) { return c == ' ' || c == '\t' || c == '\r'; }

/* Splits `text` in place at commas into trimmed fields. */
static void split(char *text) {
    field_count = 0;
    char *start = text;
    for (;;) {
        char *comma = strchr(start, ',');
        char *end = comma ? comma : start + strlen(start);
        while (start < end && blank(*start)) start++;
        while (end > start && blank(end[-1])) end--;
        if (field_count < MAX_FIELDS) fields[field_count++] = start;
        if (!comma) {
            *end = '\0';
            return;
        }
        *end = '\0';
        start = comma + 1;
    }
}

static int comment_or_blank(const char *text) {
    while (blank(*text)) text++;
    return *text == '\0' || *text == '#';
}

static int column(const char *name) {
    for (size_t i = 0; i < field_count; i++)
        if (strcmp(fields[i], name) == 0) return (int)i;
    return -1;
}

static struct columns header_columns(char *header) {
    static const char *const THERMOMETER_NAMES[RBF_THERMOMETERS] = {"temp_a", "temp_b", "temp_c", "temp_d",
                                                                   "temp_e", "temp_f", "temp_g", "temp_h"};
    static const char *const RATE_NAMES[RBF_AXES] = {"rate_x_dph", "rate_y_dph", "rate_z_dph"};
    static const char *const LOOP_NAMES[RBF_AXES] = {"temp_x_c", "temp_y_c", "temp_z_c"};
    struct columns c;
    split(header);
    c.time_s = column("time_s");
    c.rate_dph = column("rate_dph");
    c.temp_fault = column("temp_fault");
    for (int i = 0; i < RBF_THERMOMETERS; i++) c.temps[i] = column(THERMOMETER_NAMES[i]);
    c.multi_axis = 0;
    for (int a = 0; a < RBF_AXES; a++) {
        c.axis_rate[a] = column(RATE_NAMES[a]);
        c.axis_temp[a] = column(LOOP_NAMES[a]);
        c.multi_axis |= c.axis_rate[a] >= 0;
    }
    return c;
}

/* A field as a number; a field that is not one ends the replay. */
static double number(int index, unsigned long line_no) {
    char *end;
    if (index < 0 || (size_t)index >= field_count) {
        fprintf(stderr, "RUN.csv:%lu: too few fields\n", line_no);
        exit(1);
    }
    double v = strtod(fields[index], &end);
    if (end == fields[index] || *end != '\0' || !isfinite(v)) {
        fprintf(stderr, "RUN.csv:%lu: column %d: \"%s\" is not a number\n", line_no, index + 1, fields[index]);
        exit(1);
    }
    return v;
}

/* A recorded temperature as a TMP117 reports it: the nearest code of
 * 1/128 degC, saturating at the 16-bit range. */
static float tmp117(double temp_c) {
    double code = round(temp_c / 0.0078125);
    if (code >= 32767.0) code = 32767.0;
    if (code <= -32768.0) code = -32768.0;
    return (float)(int16_t)code * 0.0078125f;
}

/* The p-digit decimal nearest to the float whose exact decimal digits are
 * `exact` (value 0.exact × 10^point), a tie rounded up in magnitude, as
 * core::fmt does; written as `d.ddde±x` into `out`. */
static void nearest_digits(char *out, size_t size, const char *exact, int point, int p) {
    char d[16];
    memcpy(d, exact, (size_t)p);
    int up = exact[p] >= '5';
    for (int i = p - 1; up && i >= 0; i--) {
        up = d[i] == '9';
        d[i] = up ? '0' : (char)(d[i] + 1);
    }
    if (up) { /* 9.99… rounded up to 10.0…: one more place before the point */
        memmove(d + 1, d, (size_t)p - 1);
        d[0] = '1';
        point++;
    }
    snprintf(out, size, "%c.%.*se%d", d[0], p - 1, d + 1, point - 1);
}

/* Rust's `{}` of an f32: the shortest decimal that reads back to the same
 * float (of those, the nearest; a tie rounded up in magnitude), laid out
 * without an exponent. */
static char *put_f32(char *out, float v) {
    if (isnan(v)) return out + sprintf(out, "NaN");
    if (isinf(v)) return out + sprintf(out, v > 0 ? "inf" : "-inf");
    if (signbit(v)) *out++ = '-';
    v = fabsf(v);
    if (v == 0.0f) {
        *out++ = '0';
        return out;
    }
    /* Every float's decimal expansion is exact within 120 digits. */
    char text[160], exact[128], found[48] = "";
    snprintf(text, sizeof text, "%.119e", (double)v);
    char *e = strchr(text, 'e');
    int n = 0;
    for (char *c = text; c < e; c++)
        if (*c != '.') exact[n++] = *c;
    exact[n] = '\0';
    int point = atoi(e + 1) + 1;
    /* Below a power of two the interval that reads back is narrower under
     * the float than above it: the nearest decimal may miss it while its
     * upper neighbour reads back. */
    int power_of_two = frexpf(v, &(int){0}) == 0.5f;
    for (int p = 1; p <= 9 && !found[0]; p++) {
        char candidate[48];
        nearest_digits(candidate, sizeof candidate, exact, point, p);
        if (strtof(candidate, NULL) == v) {
            strcpy(found, candidate);
        } else if (power_of_two) {
            double ulp = pow(10.0, atoi(strchr(candidate, 'e') + 1) - (p - 1));
            snprintf(candidate, sizeof candidate, "%.*e", p - 1, strtod(candidate, NULL) + ulp);
            if (strtof(candidate, NULL) == v) strcpy(found, candidate);
        }
    }
    /* found: d[.ddd]e±x */
    char digits[16];
    n = 0;
    e = strchr(found, 'e');
    for (char *c = found; c < e; c++)
        if (*c != '.') digits[n++] = *c;
    while (n > 1 && digits[n - 1] == '0') n--;
    point = atoi(e + 1) + 1;
    if (point <= 0) {
        out += sprintf(out, "0.");
        for (int i = 0; i < -point; i++) *out++ = '0';
        memcpy(out, digits, (size_t)n);
        out += n;
    } else if (point >= n) {
        memcpy(out, digits, (size_t)n);
        out += n;
        for (int i = 0; i < point - n; i++) *out++ = '0';
    } else {
        memcpy(out, digits, (size_t)point);
        out += point;
        *out++ = '.';
        memcpy(out, digits + point, (size_t)(n - point));
        out += n - point;
    }
    return out;
}

static char *put_output(char *out, const rbf_output_t *o) {
    *out++ = ',';
    out = put_f32(out, o->bias_dph);
    *out++ = ',';
    out = put_f32(out, o->rate_comp_dph);
    return out + sprintf(out, ",%u", (unsigned)o->flags);
}

/* Reads a line without its end (\n, then any \r); 0 at the end of the file. */
static int read_line(FILE *in, unsigned long line_no) {
    if (!fgets(line, sizeof line, in)) return 0;
    size_t len = strlen(line);
    if (len > MAX_LINE) fail("RUN.csv", "a line is longer than 64 KiB");
    if (len && line[len - 1] == '\n') line[--len] = '\0';
    while (len && line[len - 1] == '\r') line[--len] = '\0';
    if (line_no == 1 && memcmp(line, "\xEF\xBB\xBF", 3) == 0) memmove(line, line + 3, len - 2);
    return 1;
}

int main(int argc, char **argv) {
    if (argc != 5) fail("usage", "replay MODEL.bin SAMPLE_RATE_HZ RUN.csv OUT.csv");
    FILE *model = fopen(argv[1], "rb");
    if (!model) fail(argv[1], "cannot open");
    size_t blob_len = fread(blob, 1, sizeof blob, model);
    fclose(model);
    float sample_rate_hz = strtof(argv[2], NULL);
    FILE *in = fopen(argv[3], "rb");
    if (!in) fail(argv[3], "cannot open");
    FILE *out = fopen(argv[4], "wb");
    if (!out) fail(argv[4], "cannot create");

    /* Metadata and comments first, then the header. */
    unsigned long line_no = 0;
    struct columns c;
    for (;;) {
        if (!read_line(in, ++line_no)) fail(argv[3], "no header line");
        if (!comment_or_blank(line)) break;
        fprintf(out, "%s\n", line);
    }
    fputs(line, out);
    c = header_columns(line);
    if (c.multi_axis) {
        for (int a = 0; a < RBF_AXES; a++)
            if (c.axis_rate[a] >= 0)
                fprintf(out, ",bias_%s_dph,rate_comp_%s_dph,flags_%s", AXIS_NAMES[a], AXIS_NAMES[a], AXIS_NAMES[a]);
        fputc('\n', out);
    } else {
        fputs(",bias_dph,rate_comp_dph,flags\n", out);
    }

    int status = c.multi_axis ? rbf_imu_load(imu_state, sizeof imu_state, blob, blob_len, sample_rate_hz)
                              : rbf_gyro_load(gyro_state, sizeof gyro_state, blob, blob_len, sample_rate_hz);
    if (status != RBF_OK) {
        fprintf(stderr, "%s: refused: %s (status %d)\n", argv[1], rbf_status_message(status), status);
        return 2;
    }

    double prev_time_s = 0.0;
    int first = 1;
    unsigned long rows = 0;
    while (read_line(in, ++line_no)) {
        if (comment_or_blank(line)) continue;
        /* The line as read, then the values (the line is split in place below). */
        if (fputs(line, out) == EOF) fail(argv[4], "cannot write");
        char *end = values;
        split(line);
        double time_s = number(c.time_s, line_no);
        float dt_s = first ? 0.0f : (float)(time_s - prev_time_s);
        prev_time_s = time_s;
        first = 0;
        int fault = c.temp_fault >= 0 && number(c.temp_fault, line_no) == 1.0;
        float temps_c[RBF_THERMOMETERS];
        for (int i = 0; i < RBF_THERMOMETERS; i++)
            temps_c[i] = (c.temps[i] < 0 || fault) ? NAN : tmp117(number(c.temps[i], line_no));
        if (c.multi_axis) {
            rbf_imu_sample_t s = {.dt_s = dt_s};
            memcpy(s.temps_c, temps_c, sizeof temps_c);
            for (int a = 0; a < RBF_AXES; a++) {
                s.rates_dph[a] = c.axis_rate[a] < 0 ? NAN : (float)number(c.axis_rate[a], line_no);
                s.loop_temps_c[a] = c.axis_temp[a] < 0 ? temps_c[RBF_LOOP_THERMOMETER]
                                    : fault            ? NAN
                                                       : tmp117(number(c.axis_temp[a], line_no));
            }
            rbf_imu_output_t o;
            if (rbf_imu_step(imu_state, sizeof imu_state, &s, &o) != RBF_OK) fail("rbf_imu_step", "refused");
            for (int a = 0; a < RBF_AXES; a++)
                if (c.axis_rate[a] >= 0) end = put_output(end, &o.axes[a]);
        } else {
            rbf_gyro_sample_t s = {.dt_s = dt_s, .rate_dph = (float)number(c.rate_dph, line_no)};
            memcpy(s.temps_c, temps_c, sizeof temps_c);
            rbf_output_t o;
            if (rbf_gyro_step(gyro_state, sizeof gyro_state, &s, &o) != RBF_OK) fail("rbf_gyro_step", "refused");
            end = put_output(end, &o);
        }
        *end++ = '\n';
        if (fwrite(values, 1, (size_t)(end - values), out) != (size_t)(end - values)) fail(argv[4], "cannot write");
        rows++;
    }
    if (fclose(out) != 0) fail(argv[4], "cannot write");
    fclose(in);
    rbf_model_info_t info;
    if (c.multi_axis)
        rbf_imu_model_info(imu_state, sizeof imu_state, &info);
    else
        rbf_gyro_model_info(gyro_state, sizeof gyro_state, &info);
    printf("replay: rows %lu model crc32 0x%08lx axes 0x%x", rows, (unsigned long)info.crc32,
           (unsigned)info.axis_mask);
    /* The provenance id finds the calibration record again (`trainer inspect`'s model_id). */
    if (info.has_provenance)
        printf(" provenance %08lx serial \"%.*s\"\n", (unsigned long)info.provenance_id, (int)info.serial_len,
               (const char *)info.serial);
    else
        printf(" provenance none\n");
    return 0;
}
