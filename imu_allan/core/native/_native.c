/*
 * Compiled kernels of imu_allan's core: the sums of squared phase differences behind
 * the overlapping Allan and Hadamard variances (NIST SP 1065 eqs. 14 and 20) and the
 * accumulator's centred running sums; for the session's input checks, the raw copy's
 * block means, the motion windows and the runs of repeated values; and for the readers,
 * a parser for the numeric fields of a CSV file, a sensor_msgs/Imu payload decoder and
 * sqlite varints.
 *
 * Plain C99: imu_allan/core/native/__init__.py loads this library with ctypes, which releases
 * the GIL for every call, so threads run these loops in parallel.  The only Python API
 * is an empty module init, so that importing imu_allan.core.native._native (as tools that
 * walk the package do) works.  Every kernel has a numpy twin that is used when the
 * library is absent; test/test_native.py checks that both give the same results.
 *
 * Summation: eight independent partial sums (they keep the adders busy and let the
 * compiler vectorise without reassociating anything itself), closed every BLOCK terms
 * into a running total, so rounding grows with the block count, not the term count.
 */

#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define BLOCK 4096
#define STRIP 2048

/*
 * Sum over j in [j0, j1) of d_j^2 with d_j = (x[j] + x[j-2m]) - 2 x[j-m] (order 2) or
 * (x[j] - x[j-3m]) - 3 (x[j-m] - x[j-2m]) (order 3).  The loops walk pointers with a
 * count, not long indices: Python's CFLAGS carry -fno-strict-overflow, under which GCC
 * cannot vectorise index arithmetic (4x slower).
 */
#define DIFF2(k) ((a[k] + c[k]) - 2.0 * b[k])
#define DIFF3(k) ((a[k] - e3[k]) - 3.0 * (b[k] - c[k]))
#define SUMSQ_BODY(DIFF, ORDER)                                                       \
    double total = 0.0;                                                               \
    for (long s = j0; s < j1; s += BLOCK) {                                           \
        long cnt = (s + BLOCK < j1 ? s + BLOCK : j1) - s;                             \
        const double *a = x + s, *b = a - m, *c = b - m;                              \
        const double *e3 = ORDER == 3 ? c - m : c;                                    \
        double p[8] = {0, 0, 0, 0, 0, 0, 0, 0};                                       \
        for (; cnt >= 8; cnt -= 8, a += 8, b += 8, c += 8, e3 += 8) {                 \
            for (int k = 0; k < 8; k++) {                                             \
                double d = DIFF(k);                                                   \
                p[k] += d * d;                                                        \
            }                                                                         \
        }                                                                             \
        for (int k = 0; k < cnt; k++) {                                               \
            double d = DIFF(k);                                                       \
            p[k] += d * d;                                                            \
        }                                                                             \
        total += ((p[0] + p[1]) + (p[2] + p[3])) + ((p[4] + p[5]) + (p[6] + p[7]));   \
    }                                                                                 \
    return total;

/* AVX2 where the CPU has it (4 doubles per instruction instead of 2), chosen at load. */
#if defined(__GNUC__) && defined(__x86_64__) && defined(__linux__)
#define WIDE __attribute__((target_clones("avx2", "default")))
#else
#define WIDE
#endif

WIDE static double sumsq2(const double *x, long m, long j0, long j1)
{
    SUMSQ_BODY(DIFF2, 2)
}

WIDE static double sumsq3(const double *x, long m, long j0, long j1)
{
    SUMSQ_BODY(DIFF3, 3)
}

static double sumsq(const double *x, long m, int order, long j0, long j1)
{
    return order == 3 ? sumsq3(x, m, j0, j1) : sumsq2(x, m, j0, j1);
}

/*
 * Running sums of centred windows (imu_allan/core/allan/accumulator.py: _phase): for every
 * axis a, r[a] = mean of win row a (w samples, row stride ld_win), x row a (row stride
 * ld_x) gets x[0] = 0 and x[j + 1] = x[j] + (win[j] - r[a]).
 */
void imu_allan_phase(const double *win, long ld_win, long n_axes, long w, double *x,
                     long ld_x, double *r)
{
    for (long a = 0; a < n_axes; a++) {
        const double *y = win + a * ld_win;
        double *out = x + a * ld_x;
        double p[4] = {0, 0, 0, 0};
        long j = 0;
        for (; j + 4 <= w; j += 4)
            for (int k = 0; k < 4; k++)
                p[k] += y[j + k];
        for (; j < w; j++)
            p[0] += y[j];
        double mean = w > 0 ? ((p[0] + p[1]) + (p[2] + p[3])) / (double)w : 0.0;
        double run = 0.0;
        out[0] = 0.0;
        for (j = 0; j < w; j++) {
            run += y[j] - mean;
            out[j + 1] = run;
        }
        r[a] = mean;
    }
}

/*
 * Streaming accumulator (imu_allan/core/allan/accumulator.py): for every axis a < n_axes
 * (row a of x, row stride ld) and cluster size ms[i], add the squared second
 * differences ending at j_first .. j_last (those with j >= 2 ms[i]) to
 * sums[i * n_axes + a].
 */
void imu_allan_acc_sums(const double *x, long ld, long n_axes, long j_first, long j_last,
                        const int64_t *ms, long k, double *sums)
{
    /* Axis by axis: one row (a few hundred kB) stays in L2 for all the taus. */
    for (long a = 0; a < n_axes; a++) {
        for (long i = 0; i < k; i++) {
            long m = (long)ms[i];
            long j0 = j_first > 2 * m ? j_first : 2 * m;
            if (j0 <= j_last)
                sums[i * n_axes + a] += sumsq2(x + a * ld, m, j0, j_last + 1);
        }
    }
}

/*
 * Batch curve (imu_allan/core/allan/kernels.py): sum over every j in [order m, n) of
 * the squared order-th lag-m difference of the phase row x (n,), order 2 or 3.
 * For long lags the row is walked as a (n / m, m) matrix in column strips down the
 * rows, so the rows j - m, j - 2m (, j - 3m) are still in cache: each sample is read
 * from memory about once per tau, not order + 1 times.
 */
double imu_allan_diff_sumsq(const double *x, long n, long m, long order)
{
    long first = order * m;
    if (first >= n)
        return NAN;
    if (m <= 4 * STRIP)
        return sumsq(x, m, (int)order, first, n);
    double total = 0.0;
    for (long c0 = 0; c0 < m; c0 += STRIP) {
        long w = c0 + STRIP < m ? STRIP : m - c0;
        for (long r = first + c0; r < n; r += m) {
            long e = r + w < n ? r + w : n;
            total += sumsq(x, m, (int)order, r, e);
        }
    }
    return total;
}

/* ------------------------------------------------------------------ CSV fields */

static int is_blank(char ch)
{
    return ch == ' ' || ch == '\t' || ch == '\r';
}

static int is_digit(char ch)
{
    return (unsigned char)(ch - '0') < 10;
}

/*
 * The value of the eight ASCII digits at p, or -1 when one of them is not a digit:
 * one 64-bit load and three multiplies instead of eight dependent steps (the bytes
 * are paired, then the pairs, then the quads; little-endian byte order).
 */
static int64_t eight_digits(const char *p)
{
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    const uint64_t hi = 0xF0F0F0F0F0F0F0F0ULL, zeros = 0x3030303030303030ULL;
    uint64_t v;
    memcpy(&v, p, 8);
    /* Each byte in '0'..'9': high nibble 3, and still 3 after adding 6. */
    if ((v & hi) != zeros || ((v + 0x0606060606060606ULL) & hi) != zeros)
        return -1;
    v -= zeros;
    v = v * 10 + (v >> 8);
    v = (((v & 0x000000FF000000FFULL) * (100 + (1000000ULL << 32))) +
         (((v >> 16) & 0x000000FF000000FFULL) * (1 + (10000ULL << 32)))) >> 32;
    return (int64_t)v;
#else
    (void)p;
    return -1;
#endif
}

/*
 * Parse [blanks][+-]digits[.digits][(e|E)[+-]digits][blanks] at *pp, stopping at the
 * first other character (where *pp is left).  Returns -1 when there is no such number
 * (nan, inf, hex, an empty field, text): the caller then hands the file to numpy's
 * parser.  Else returns 22 + e and sets *out to a signed integer mantissa below 2^53
 * (exact in a double): the value is *out * 10^e, which apply_scales() computes in one
 * correctly rounded operation (Clinger's fast path) for a whole block of fields at
 * once, so the divisions overlap instead of stalling the parse one by one.  Numbers
 * outside the fast path (more than 19 digits, a mantissa above 2^53, |e| > 22) are
 * converted here by glibc's strtod, which rounds correctly, and get 22 (times one).
 */
static int parse_number(const char **pp, const char *end, double *out)
{
    const char *p = *pp;
    while (p < end && is_blank(*p))
        p++;
    const char *start = p;
    int neg = 0;
    if (p < end && (*p == '+' || *p == '-')) {
        neg = *p == '-';
        p++;
    }
    uint64_t mant = 0;
    int digits = 0, long_mant = 0, any = 0; /* long_mant: over 19 digits, for strtod */
    long frac = 0;
    for (; p < end && *p == '0'; p++)
        any = 1;
    for (int64_t d8; digits <= 11 && end - p >= 8 && (d8 = eight_digits(p)) >= 0;
         p += 8, digits += 8, any = 1)
        mant = mant * 100000000 + (uint64_t)d8;
    for (; p < end && is_digit(*p); p++, any = 1) {
        if (digits < 19) {
            mant = mant * 10 + (uint64_t)(*p - '0');
            digits++;
        } else {
            long_mant = 1;
        }
    }
    if (p < end && *p == '.') {
        p++;
        if (mant == 0)
            for (; p < end && *p == '0'; p++, frac++)
                any = 1;
        for (int64_t d8; digits <= 11 && end - p >= 8 && (d8 = eight_digits(p)) >= 0;
             p += 8, digits += 8, frac += 8, any = 1)
            mant = mant * 100000000 + (uint64_t)d8;
        for (; p < end && is_digit(*p); p++, any = 1) {
            if (digits < 19) {
                mant = mant * 10 + (uint64_t)(*p - '0');
                digits++;
                frac++;
            } else {
                long_mant = 1;
            }
        }
    }
    if (!any)
        return -1;
    long exp10 = 0;
    if (p < end && (*p == 'e' || *p == 'E')) {
        int eneg = 0, edig = 0;
        p++;
        if (p < end && (*p == '+' || *p == '-')) {
            eneg = *p == '-';
            p++;
        }
        for (; p < end && is_digit(*p); p++, edig++)
            if (exp10 < 100000)
                exp10 = exp10 * 10 + (*p - '0');
        if (!edig)
            return -1;
        if (eneg)
            exp10 = -exp10;
    }
    const char *stop = p;
    while (p < end && is_blank(*p))
        p++;
    *pp = p;
    long e = exp10 - frac;
    if (mant == 0 || (mant <= (1ULL << 53) && !long_mant && e >= -22 && e <= 22)) {
        *out = neg ? -(double)mant : (double)mant;
        return mant == 0 ? 22 : (int)(22 + e);
    }
    {
        char buf[512];
        long n = stop - start;
        if (n >= (long)sizeof buf)
            return -1;
        for (long k = 0; k < n; k++)
            buf[k] = start[k];
        buf[n] = '\0';
        char *tail;
        *out = strtod(buf, &tail);
        if (tail != buf + n)
            return -1;
        return 22;
    }
}

/* Fields per block of apply_scales(): their scale indices stay on the stack. */
#define FIELDS 4096

#define ONES22 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1
/* Index 22 + e: 10^e for e >= 0 (else 1), and 10^-e for e < 0 (else 1). */
static const double MUL[45] = {
    ONES22, 1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12,
    1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};
static const double DIV[45] = {
    1e22, 1e21, 1e20, 1e19, 1e18, 1e17, 1e16, 1e15, 1e14, 1e13, 1e12, 1e11, 1e10,
    1e9, 1e8, 1e7, 1e6, 1e5, 1e4, 1e3, 1e2, 1e1, 1, ONES22};

/* values[i] *= 10^(scale[i] - 22): one rounding each, as one of the factors is 1. */
static void apply_scales(double *values, const signed char *scale, long n)
{
    for (long i = 0; i < n; i++)
        values[i] = values[i] * MUL[scale[i]] / DIV[scale[i]];
}

/*
 * Parse the data rows of a CSV text into table (capacity rows of n_cols doubles):
 * comma-separated fields, '#' starts a comment, blank and comment-only lines are
 * skipped.  One pass over the text.  Returns the number of rows, or -1 when a row has
 * another field count, a field is not a plain decimal number, or there are more rows
 * than capacity.
 */
long imu_allan_parse_csv(const char *text, long len, long n_cols, double *table,
                         long capacity)
{
    const char *p = text, *end = text + len;
    long rows = 0, done = 0; /* fields scaled so far */
    signed char scale[FIELDS];
    if (n_cols > FIELDS)
        return -1;
    while (p < end) {
        while (p < end && is_blank(*p))
            p++;
        if (p < end && *p != '\n' && *p != '#') {
            if (rows >= capacity)
                return -1;
            if ((rows + 1) * n_cols - done > FIELDS) {
                apply_scales(table + done, scale, rows * n_cols - done);
                done = rows * n_cols;
            }
            double *row = table + rows * n_cols;
            for (long col = 0;; col++) {
                int sc;
                if (col >= n_cols || (sc = parse_number(&p, end, row + col)) < 0)
                    return -1;
                scale[rows * n_cols + col - done] = (signed char)sc;
                if (p == end || *p == '\n' || *p == '#') {
                    if (col + 1 != n_cols)
                        return -1;
                    break;
                }
                if (*p++ != ',')
                    return -1;
            }
            rows++;
        }
        while (p < end && *p != '\n')   /* a comment, or the end of the line */
            p++;
        p++;
    }
    apply_scales(table + done, scale, rows * n_cols - done);
    return rows;
}

/* ------------------------------------------------------- sensor_msgs/Imu payloads */

static uint32_t load_u32(const uint8_t *p, int big)
{
    uint32_t v;
    memcpy(&v, p, 4);
    return big ? __builtin_bswap32(v) : v;
}

static double load_f64(const uint8_t *p, int big)
{
    uint64_t v;
    double d;
    memcpy(&v, p, 8);
    if (big)
        v = __builtin_bswap64(v);
    memcpy(&d, &v, 8);
    return d;
}

/*
 * Decode n serialised sensor_msgs/Imu payloads held in buf (size bytes), payload i at
 * starts[i] with lengths[i] bytes (imu_allan/io/imu_cdr.py: decode_imu_payloads, the
 * same layout rules).  ROS 2 CDR: encapsulation 0x00 0x00 (big-endian) or 0x00 0x01
 * (little-endian), stamp sec int32 and nanosec uint32 at byte 4, frame_id length at
 * byte 12 (at least 1: the NUL), the 37 doubles 8-aligned after the encapsulation;
 * ROS 1 (ros1 != 0): seq, secs, nsecs uint32, frame_id length at byte 12, the doubles
 * right after the frame_id, little-endian.  For every payload that fits its layout:
 * stamp_ns[i], samples[6 i .. 6 i + 5] (angular_velocity, linear_acceleration) and
 * ok[i] = 1; otherwise ok[i] = 0 and nothing else is written (the caller decodes those
 * with rosbags).  Returns the number of payloads that did not fit.
 */
long imu_allan_decode_imu(const uint8_t *buf, long size, const int64_t *starts,
                          const int64_t *lengths, long n, long ros1, int64_t *stamp_ns,
                          double *samples, uint8_t *ok)
{
    long misfits = 0;
    for (long i = 0; i < n; i++) {
        int64_t start = starts[i], len = lengths[i];
        ok[i] = 0;
        if (start < 0 || len < 16 || start > size - len) {
            misfits++;
            continue;
        }
        const uint8_t *p = buf + start;
        int big = 0;
        int64_t frame_len, at;
        if (ros1) {
            frame_len = load_u32(p + 12, 0);
            at = 16 + frame_len;
        } else {
            if (p[0] != 0 || p[1] > 1) {
                misfits++;
                continue;
            }
            big = p[1] == 0;
            frame_len = load_u32(p + 12, big);
            if (frame_len < 1) {
                misfits++;
                continue;
            }
            at = 4 + (12 + frame_len + 7) / 8 * 8;
        }
        if (frame_len >= len || at + 37 * 8 > len) {
            misfits++;
            continue;
        }
        uint32_t sec = load_u32(p + 4, big), nsec = load_u32(p + 8, big);
        stamp_ns[i] = (ros1 ? (int64_t)sec : (int64_t)(int32_t)sec) * 1000000000LL + nsec;
        for (int k = 0; k < 3; k++) {
            samples[6 * i + k] = load_f64(p + at + 104 + 8 * k, big);
            samples[6 * i + 3 + k] = load_f64(p + at + 200 + 8 * k, big);
        }
        ok[i] = 1;
    }
    return misfits;
}

/* ------------------------------------------------------------ sqlite varints */

/*
 * Decode one sqlite varint at each offset pos[i] of buf (size bytes): big-endian groups
 * of 7 bits with the high bit saying "more", the 9th byte taking all 8 bits (sqlite
 * file format, section 2.1).  Sets value[i] and length[i] (bytes used).  Returns 0, or
 * -1 when a varint runs past the buffer (imu_allan/io/bags/rosbag2_sqlite.py: _varint,
 * whose numpy twin raises IndexError there).
 */
long imu_allan_varints(const uint8_t *buf, long size, const int64_t *pos, long n,
                       int64_t *value, int64_t *length)
{
    for (long i = 0; i < n; i++) {
        int64_t p = pos[i];
        if (p < 0)
            return -1;
        uint64_t v = 0;
        int k = 0;
        for (;; k++) {
            if (p + k >= size)
                return -1;
            uint8_t b = buf[p + k];
            if (k == 8) {
                v = (v << 8) | b;
                break;
            }
            v = (v << 7) | (b & 0x7F);
            if (b < 0x80)
                break;
        }
        value[i] = (int64_t)v;
        length[i] = k + 1;
    }
    return 0;
}

/* ------------------------------------------------------------- input checks */

/*
 * Block means of the raw copy (imu_allan/core/allan/raw.py: _means): out row r (n_cols
 * values, contiguous) = (((y[r f] + y[r f + 1]) + y[r f + 2]) + ...) * (1 / f) over f =
 * factor >= 2 rows of y (row stride ld): the additions of the numpy twin, in its order,
 * so both give the same bits.
 */
void imu_allan_block_means(const double *y, long ld, long n_out, long n_cols, long factor,
                           double *out)
{
    double scale = 1.0 / (double)factor;
    for (long r = 0; r < n_out; r++) {
        const double *row = y + r * factor * ld;
        double *o = out + r * n_cols;
        for (long c = 0; c < n_cols; c++)
            o[c] = row[c] + row[ld + c];
        for (long k = 2; k < factor; k++)
            for (long c = 0; c < n_cols; c++)
                o[c] += row[k * ld + c];
        for (long c = 0; c < n_cols; c++)
            o[c] *= scale;
    }
}

#define MAX_AXES 16

/*
 * Motion gate (imu_allan/pipeline/checks.py: _still_run): windows of win rows of y
 * (row stride ld, n_axes <= MAX_AXES columns), one after another.  Each axis' mean and
 * standard deviation (ddof 0) come from the deviations to the window's first row; a
 * window moved when an axis' mean is more than thr[a] off ref_mean[a] or its std more
 * than ratio_limit times ref_std[a].  Each still window pulls the reference towards its
 * mean (ref_mean = 0.99 ref_mean + 0.01 mean, so slow bias drift is not motion).
 * Returns the number of still windows before the first that moved (n_windows when none
 * did); that window's mean and std are left in mean_out and std_out.
 */
long imu_allan_motion_scan(const double *y, long ld, long n_windows, long win, long n_axes,
                           const double *thr, double ratio_limit, double *ref_mean,
                           const double *ref_std, double *mean_out, double *std_out)
{
    if (n_axes > MAX_AXES)
        return -1;
    for (long w = 0; w < n_windows; w++) {
        const double *b = y + w * win * ld;
        double s[MAX_AXES] = {0}, s2[MAX_AXES] = {0};
        for (long i = 1; i < win; i++) {
            const double *row = b + i * ld;
            for (long a = 0; a < n_axes; a++) {
                double d = row[a] - b[a];
                s[a] += d;
                s2[a] += d * d;
            }
        }
        int moving = 0;
        for (long a = 0; a < n_axes; a++) {
            double shift = s[a] / (double)win;
            double var = s2[a] / (double)win - shift * shift;
            mean_out[a] = b[a] + shift;
            std_out[a] = sqrt(var > 0.0 ? var : 0.0);
            if (fabs(mean_out[a] - ref_mean[a]) > thr[a] || std_out[a] / ref_std[a] > ratio_limit)
                moving = 1;
        }
        if (moving)
            return w;
        for (long a = 0; a < n_axes; a++)
            ref_mean[a] = 0.99 * ref_mean[a] + 0.01 * mean_out[a];
    }
    return n_windows;
}

/*
 * Frozen-axis check (imu_allan/pipeline/checks.py: _repeat_runs): per axis a, the run
 * of samples equal to the one before (last[a] before row 0) goes on from run[a]; on
 * return run[a] is the run that ends the block and longest[a] the longest seen,
 * run[a] on entry included.
 */
void imu_allan_repeats(const double *y, long ld, long n, long n_axes, const double *last,
                       int64_t *run, int64_t *longest)
{
    for (long a = 0; a < n_axes; a++) {
        int64_t r = run[a], top = run[a];
        double prev = last[a];
        for (long i = 0; i < n; i++) {
            double v = y[i * ld + a];
            r = v == prev ? r + 1 : 0;
            top = r > top ? r : top;
            prev = v;
        }
        run[a] = r;
        longest[a] = top;
    }
}

/* ------------------------------------------------ the fit's model and covariance */

/*
 * h(x) / x^2 of the Gauss-Markov Allan variance shape (imu_allan/core/noise/model.py,
 * _gm_shape): below x = 0.05 its Taylor series, the n_c coefficients c highest power
 * first by Horner (h(x) / x^3) times x; else (x - 1.5 + 2 e - 0.5 e e) / (x x) with
 * e = exp(-x).  The design matrix of every fit evaluates this thousands of times on a
 * few tens of taus, where numpy's per-call overhead was most of the cost.
 */
void imu_allan_gm_shape(const double *x, long n, const double *c, long n_c, double *out)
{
    for (long i = 0; i < n; i++) {
        double xi = x[i];
        if (xi < 0.05) {
            double acc = c[0];
            for (long k = 1; k < n_c; k++) {
                acc *= xi;
                acc += c[k];
            }
            out[i] = acc * xi;
        } else {
            double e = exp(-xi);
            out[i] = (xi - 1.5 + 2.0 * e - 0.5 * e * e) / (xi * xi);
        }
    }
}

/*
 * Stencil sums of the first-order Gauss-Markov generalised covariance at the quadrature
 * nodes (imu_allan/core/fit/covariance.py, _LagQuadrature.gamma):
 * out[k] = sum_s w[s] g(lags[s n + k]) with g(u) = -(T^3 / 2) (e^-x - 1 + x), x = |u| / T,
 * and x^2 (1/2 - x (1/6 - x / 24)) for e^-x - 1 + x below x = 1e-3, term by term as
 * the numpy twin (model.py, _gcov_gauss_markov) computes them; from x = 0.5 on, where
 * nothing cancels, exp (faster than expm1) gives e^-x.  One pass over the lags instead
 * of a handful of (n_s, n) temporaries.
 */
void imu_allan_gm_stencil(const double *lags, long n, long n_s, const double *w, double T,
                          double *out)
{
    const double inv = 1.0 / T, scale = -0.5 * pow(T, 3.0);
    for (long k = 0; k < n; k++)
        out[k] = 0.0;
    for (long s = 0; s < n_s; s++) {
        const double *u = lags + s * n;
        const double ws = w[s];
        for (long k = 0; k < n; k++) {
            double x = fabs(u[k]) * inv;
            double h = x < 1e-3 ? x * x * (0.5 - x * (1.0 / 6.0 - x / 24.0))
                       : x < 0.5 ? expm1(-x) + x : (exp(-x) - 1.0) + x;
            out[k] += ws * (h * scale);
        }
    }
}

/*
 * Per-segment sums of weight g_a g_b over the quadrature nodes (covariance.py,
 * _LagQuadrature.blocks): out[p n_seg + i] = sum over nodes j of segment i
 * ([starts[i], starts[i + 1]), the last one to n) of weight[j] g[a_p][j] g[b_p][j].
 * Eight partial sums per segment, as everywhere in this file.
 */
void imu_allan_pair_sums(const double *g, long n, const double *weight,
                         const int64_t *starts, long n_seg, const int64_t *a_idx,
                         const int64_t *b_idx, long n_ab, double *out)
{
    for (long i = 0; i < n_seg; i++) {
        int64_t j0 = starts[i], j1 = i + 1 < n_seg ? starts[i + 1] : n;
        for (long p = 0; p < n_ab; p++) {
            const double *ga = g + a_idx[p] * n, *gb = g + b_idx[p] * n;
            double acc[8] = {0, 0, 0, 0, 0, 0, 0, 0};
            int64_t j = j0;
            for (; j + 8 <= j1; j += 8)
                for (int k = 0; k < 8; k++)
                    acc[k] += (weight[j + k] * ga[j + k]) * gb[j + k];
            for (int k = 0; j < j1; j++, k++)
                acc[k] += (weight[j] * ga[j]) * gb[j];
            out[p * n_seg + i] = ((acc[0] + acc[1]) + (acc[2] + acc[3]))
                + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
        }
    }
}

/* ------------------------------------------------------------- module init */

static struct PyModuleDef native_module = {
    PyModuleDef_HEAD_INIT, "_native",
    "Compiled kernels of imu_allan's core, called through ctypes (imu_allan.core.native).",
    -1, NULL, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__native(void)
{
    return PyModule_Create(&native_module);
}
