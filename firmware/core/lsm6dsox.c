/* LSM6DSOX register access over the platform's I2C bus (see lsm6dsox.h). */
#include "lsm6dsox.h"

#include <stddef.h>

#define RESET_TIMEOUT_US 50000u
#define RESET_POLL_US 100u
#define SELF_TEST_SETTLE_US 100000u
#define SELF_TEST_SAMPLES 5
#define SELF_TEST_ACCEL_ODR_CODE 3u /* 52 Hz */
#define SELF_TEST_ACCEL_FS_G 4u
#define SELF_TEST_GYRO_ODR_CODE 5u  /* 208 Hz */
#define SELF_TEST_GYRO_FS_DPS 2000u
#define FREQ_FINE_STEP_PPM 1500     /* 0.15 % per step of INTERNAL_FREQ_FINE */

/* The datasheet's labels, for messages. The chip runs at 6666.67 Hz / ODR_Coeff with ODR_Coeff
 * = 512, 256, ... 1 (AN5272): "12.5 Hz" is 13.02 Hz, "104 Hz" 104.17 Hz. */
static const uint32_t odr_label_mhz_table[LSM_ODR_CODE_MAX + 1] = {
    0, 12500, 26000, 52000, 104000, 208000, 417000, 833000, 1667000, 3333000, 6667000,
};
/* Samples to discard after the ODR is set (turn-on transient): accelerometer, gyroscope. The
 * settling figures plus two, as ST's drivers do; where the figures come from and which are
 * extrapolated: drivers/lsm6dsox.py, TURN_ON_DISCARD (the host tests compare the tables). */
static const uint16_t turn_on_discard_table[LSM_ODR_CODE_MAX + 1][2] = {
    {0, 0}, {3, 4}, {3, 7}, {3, 9}, {4, 14}, {4, 22}, {4, 38}, {5, 72}, {5, 137}, {6, 272},
    {7, 541},
};

static bool valid_odr_code(uint8_t odr_code)
{
    return odr_code >= LSM_ODR_CODE_MIN && odr_code <= LSM_ODR_CODE_MAX;
}

uint32_t lsm_odr_label_mhz(uint8_t odr_code)
{
    return valid_odr_code(odr_code) ? odr_label_mhz_table[odr_code] : 0;
}

/* ODR in mHz with the clock trim `trim_ppm` (1 000 000 = untrimmed), rounded:
 * 20 000 000 / 3 mHz / 2^(10 - code) x trim. */
static uint32_t odr_trimmed_mhz(uint8_t odr_code, int64_t trim_ppm)
{
    if (!valid_odr_code(odr_code))
        return 0;
    int64_t numerator = (int64_t)20000000 * trim_ppm;
    int64_t denominator = (int64_t)3 * ((int64_t)1 << (LSM_ODR_CODE_MAX - odr_code)) * 1000000;
    return (uint32_t)((numerator + denominator / 2) / denominator);
}

uint32_t lsm_odr_nominal_mhz(uint8_t odr_code)
{
    return odr_trimmed_mhz(odr_code, 1000000);
}

uint16_t lsm_turn_on_discard(uint8_t odr_code, bool gyro)
{
    return valid_odr_code(odr_code) ? turn_on_discard_table[odr_code][gyro ? 1 : 0] : 0;
}

int lsm_fs_xl_code(uint8_t accel_fs_g)
{
    switch (accel_fs_g) { /* CTRL1_XL FS_XL[1:0]: not in order */
    case 2: return 0;
    case 16: return 1;
    case 4: return 2;
    case 8: return 3;
    default: return -1;
    }
}

int lsm_fs_g_code(uint16_t gyro_fs_dps)
{
    switch (gyro_fs_dps) { /* CTRL2_G FS_G[1:0] with FS_125 as the low bit */
    case 250: return 0;
    case 125: return 1;
    case 500: return 2;
    case 1000: return 4;
    case 2000: return 6;
    default: return -1;
    }
}

static uint8_t ctrl1_xl(uint8_t odr_code, uint8_t accel_fs_g)
{
    return (uint8_t)((odr_code << 4) | (lsm_fs_xl_code(accel_fs_g) << 2));
}

static uint8_t ctrl2_g(uint8_t odr_code, uint16_t gyro_fs_dps)
{
    return (uint8_t)((odr_code << 4) | (lsm_fs_g_code(gyro_fs_dps) << 1));
}

bool lsm_configuration_sequence(const lsm_settings *s, lsm_write out[LSM_SEQUENCE_LENGTH])
{
    if (!lsm_odr_nominal_mhz(s->odr_code) || lsm_fs_xl_code(s->accel_fs_g) < 0 ||
        lsm_fs_g_code(s->gyro_fs_dps) < 0)
        return false;
    const lsm_write sequence[LSM_SEQUENCE_LENGTH] = {
        {LSM_CTRL3_C, LSM_CTRL3_C_SW_RESET},
        {LSM_CTRL3_C, LSM_CTRL3_C_BDU_IF_INC},
        {LSM_CTRL9_XL, LSM_CTRL9_XL_I3C_DISABLED},
        {LSM_FIFO_CTRL3, (uint8_t)((s->odr_code << 4) | s->odr_code)},
        {LSM_FIFO_CTRL4, LSM_FIFO_CTRL4_BATCHING | LSM_FIFO_MODE_CONTINUOUS},
        {LSM_CTRL10_C, LSM_CTRL10_C_TIMESTAMP_EN},
        {LSM_CTRL1_XL, ctrl1_xl(s->odr_code, s->accel_fs_g)},
        {LSM_CTRL2_G, ctrl2_g(s->odr_code, s->gyro_fs_dps)},
    };
    for (size_t i = 0; i < LSM_SEQUENCE_LENGTH; i++)
        out[i] = sequence[i];
    return true;
}

static int write_reg(lsm6dsox *chip, uint8_t reg, uint8_t value)
{
    const fw_platform *p = chip->platform;
    return p->i2c_write(p->ctx, chip->address, reg, &value, 1) ? LSM_ERR_BUS : LSM_OK;
}

static int read_regs(lsm6dsox *chip, uint8_t reg, uint8_t *data, size_t length)
{
    const fw_platform *p = chip->platform;
    return p->i2c_read(p->ctx, chip->address, reg, data, length) ? LSM_ERR_BUS : LSM_OK;
}

void lsm_init(lsm6dsox *chip, const fw_platform *platform)
{
    chip->platform = platform;
    chip->address = 0;
    chip->who_am_i = 0;
    chip->freq_fine = 0;
    chip->configured = false;
    chip->settings = (lsm_settings){4, 4, 250};
}

int lsm_probe(lsm6dsox *chip)
{
    static const uint8_t addresses[] = {LSM6DSOX_ADDRESS_SA0_LOW, LSM6DSOX_ADDRESS_SA0_HIGH};
    const fw_platform *p = chip->platform;
    chip->configured = false;
    chip->who_am_i = 0;
    bool answered = false;
    for (size_t i = 0; i < sizeof addresses; i++) {
        uint8_t value = 0;
        if (p->i2c_read(p->ctx, addresses[i], LSM_WHO_AM_I, &value, 1))
            continue;
        if (!answered) { /* report the first thing that answered */
            answered = true;
            chip->who_am_i = value;
            chip->address = addresses[i];
        }
        if (value == LSM6DSOX_WHO_AM_I_VALUE) {
            chip->who_am_i = value;
            chip->address = addresses[i];
            return LSM_OK;
        }
    }
    if (!answered) {
        chip->address = 0;
        return LSM_ERR_BUS;
    }
    return LSM_ERR_WHO_AM_I;
}

int lsm_probe_at(lsm6dsox *chip, uint8_t address)
{
    const fw_platform *p = chip->platform;
    uint8_t value = 0;
    chip->configured = false;
    chip->who_am_i = 0;
    if (p->i2c_read(p->ctx, address, LSM_WHO_AM_I, &value, 1)) {
        chip->address = 0;
        return LSM_ERR_BUS;
    }
    chip->address = address;
    chip->who_am_i = value;
    return value == LSM6DSOX_WHO_AM_I_VALUE ? LSM_OK : LSM_ERR_WHO_AM_I;
}

static int wait_for_reset(lsm6dsox *chip)
{
    const fw_platform *p = chip->platform;
    uint32_t start = p->micros(p->ctx);
    for (;;) {
        uint8_t ctrl3 = 0;
        /* The chip may not acknowledge while it resets: only the timeout decides. */
        int err = read_regs(chip, LSM_CTRL3_C, &ctrl3, 1);
        if (!err && !(ctrl3 & LSM_CTRL3_C_SW_RESET))
            return LSM_OK;
        if ((uint32_t)(p->micros(p->ctx) - start) > RESET_TIMEOUT_US)
            return err ? err : LSM_ERR_RESET;
        p->delay_us(p->ctx, RESET_POLL_US);
    }
}

int lsm_configure(lsm6dsox *chip, const lsm_settings *settings)
{
    lsm_write sequence[LSM_SEQUENCE_LENGTH];
    if (!chip->address || !lsm_configuration_sequence(settings, sequence))
        return LSM_ERR_BUS;
    chip->configured = false;
    for (size_t i = 0; i < LSM_SEQUENCE_LENGTH; i++) {
        int err = write_reg(chip, sequence[i].reg, sequence[i].value);
        if (!err && sequence[i].reg == LSM_CTRL3_C && (sequence[i].value & LSM_CTRL3_C_SW_RESET))
            err = wait_for_reset(chip);
        if (err)
            return err;
    }
    /* Read back FIFO_CTRL3 .. CTRL10_C in one burst and compare the final values. */
    uint8_t readback[LSM_CTRL10_C - LSM_FIFO_CTRL3 + 1];
    int err = read_regs(chip, LSM_FIFO_CTRL3, readback, sizeof readback);
    if (err)
        return err;
    for (size_t i = 1; i < LSM_SEQUENCE_LENGTH; i++) {
        bool last_write = true; /* only the last write to a register counts */
        for (size_t j = i + 1; j < LSM_SEQUENCE_LENGTH; j++)
            if (sequence[j].reg == sequence[i].reg)
                last_write = false;
        if (last_write && readback[sequence[i].reg - LSM_FIFO_CTRL3] != sequence[i].value)
            return LSM_ERR_READBACK;
    }
    uint8_t fine = 0;
    err = read_regs(chip, LSM_INTERNAL_FREQ_FINE, &fine, 1);
    if (err)
        return err;
    chip->freq_fine = (int8_t)fine;
    chip->configured_us = chip->platform->micros(chip->platform->ctx);
    chip->settings = *settings;
    chip->configured = true;
    return LSM_OK;
}

int lsm_fifo_reset(lsm6dsox *chip, bool restart)
{
    int err = write_reg(chip, LSM_FIFO_CTRL4, LSM_FIFO_CTRL4_BATCHING | LSM_FIFO_MODE_BYPASS);
    if (!err && restart)
        err = write_reg(chip, LSM_FIFO_CTRL4, LSM_FIFO_CTRL4_BATCHING | LSM_FIFO_MODE_CONTINUOUS);
    return err;
}

int lsm_fifo_status(lsm6dsox *chip, uint16_t *words, bool *overrun)
{
    uint8_t status[2];
    int err = read_regs(chip, LSM_FIFO_STATUS1, status, sizeof status);
    if (err)
        return err;
    *words = (uint16_t)(status[0] | ((status[1] & LSM_FIFO_STATUS2_DIFF_HIGH) << 8));
    *overrun = (status[1] & (LSM_FIFO_STATUS2_OVR_IA | LSM_FIFO_STATUS2_OVR_LATCHED)) != 0;
    return LSM_OK;
}

int lsm_fifo_read(lsm6dsox *chip, uint8_t *out, uint16_t words)
{
    return read_regs(chip, LSM_FIFO_DATA_OUT_TAG, out, (size_t)words * LSM_FIFO_WORD_BYTES);
}

int lsm_read_temperature(lsm6dsox *chip, int16_t *raw)
{
    uint8_t data[2];
    int err = read_regs(chip, LSM_OUT_TEMP_L, data, sizeof data);
    if (!err)
        *raw = (int16_t)(data[0] | (data[1] << 8));
    return err;
}

int lsm_read_timestamp(lsm6dsox *chip, uint32_t *ticks)
{
    uint8_t data[4];
    int err = read_regs(chip, LSM_TIMESTAMP0, data, sizeof data);
    if (!err)
        *ticks = (uint32_t)data[0] | ((uint32_t)data[1] << 8) | ((uint32_t)data[2] << 16) |
                 ((uint32_t)data[3] << 24);
    return err;
}

/* 1 + 0.0015 * FREQ_FINE, in parts per million. */
static int64_t trim_ppm(const lsm6dsox *chip)
{
    return 1000000 + (int64_t)FREQ_FINE_STEP_PPM * chip->freq_fine;
}

static int64_t divide_rounded(int64_t numerator, int64_t denominator)
{
    return (numerator + denominator / 2) / denominator;
}

uint32_t lsm_odr_mhz(const lsm6dsox *chip)
{
    return odr_trimmed_mhz(chip->settings.odr_code, trim_ppm(chip));
}

uint32_t lsm_tick_ns(const lsm6dsox *chip)
{
    return (uint32_t)divide_rounded(25000LL * 1000000, trim_ppm(chip));
}

/* The next new sample of one sensor (STATUS_REG ready bit), as three int16 axes. */
static int next_sample(lsm6dsox *chip, uint8_t ready_bit, uint8_t out_reg, uint32_t period_us,
                       int32_t xyz[3])
{
    const fw_platform *p = chip->platform;
    uint32_t start = p->micros(p->ctx);
    uint32_t timeout = 10u * period_us + 50000u;
    for (;;) {
        uint8_t status = 0;
        int err = read_regs(chip, LSM_STATUS_REG, &status, 1);
        if (err)
            return err;
        if (status & ready_bit)
            break;
        if ((uint32_t)(p->micros(p->ctx) - start) > timeout)
            return LSM_ERR_NO_DATA;
        p->delay_us(p->ctx, period_us / 4u);
    }
    uint8_t data[6];
    int err = read_regs(chip, out_reg, data, sizeof data);
    if (err)
        return err;
    for (int axis = 0; axis < 3; axis++)
        xyz[axis] = (int16_t)(data[2 * axis] | (data[2 * axis + 1] << 8));
    return LSM_OK;
}

/* Sum of SELF_TEST_SAMPLES samples after dropping the first one. */
static int sum_samples(lsm6dsox *chip, uint8_t ready_bit, uint8_t out_reg, uint32_t period_us,
                       int32_t sum[3])
{
    sum[0] = sum[1] = sum[2] = 0;
    for (int i = 0; i <= SELF_TEST_SAMPLES; i++) {
        int32_t xyz[3];
        int err = next_sample(chip, ready_bit, out_reg, period_us, xyz);
        if (err)
            return err;
        if (i == 0)
            continue;
        for (int axis = 0; axis < 3; axis++)
            sum[axis] += xyz[axis];
    }
    return LSM_OK;
}

/* Output change (self-test on minus off) per axis, as sums over SELF_TEST_SAMPLES samples. */
static int self_test_change(lsm6dsox *chip, uint8_t ready_bit, uint8_t out_reg,
                            uint8_t enable, uint32_t period_us, int32_t change[3])
{
    const fw_platform *p = chip->platform;
    int32_t off[3], on[3];
    p->delay_us(p->ctx, SELF_TEST_SETTLE_US);
    int err = sum_samples(chip, ready_bit, out_reg, period_us, off);
    if (!err)
        err = write_reg(chip, LSM_CTRL5_C, enable);
    if (!err) {
        p->delay_us(p->ctx, SELF_TEST_SETTLE_US);
        err = sum_samples(chip, ready_bit, out_reg, period_us, on);
    }
    int off_err = write_reg(chip, LSM_CTRL5_C, 0); /* always try to switch the force off */
    if (err)
        return err;
    if (off_err)
        return off_err;
    for (int axis = 0; axis < 3; axis++)
        change[axis] = on[axis] - off[axis];
    return LSM_OK;
}

/* sum of `SELF_TEST_SAMPLES` LSB x sensitivity (micro-units per LSB) -> rounded units. */
static int16_t mean_in_units(int32_t sum_lsb, int32_t micro_per_lsb)
{
    int64_t scaled = (int64_t)sum_lsb * micro_per_lsb;
    int64_t denominator = (int64_t)SELF_TEST_SAMPLES * 1000000;
    int64_t rounded = scaled >= 0 ? (scaled + denominator / 2) / denominator
                                  : -((-scaled + denominator / 2) / denominator);
    if (rounded > INT16_MAX)
        return INT16_MAX;
    if (rounded < INT16_MIN)
        return INT16_MIN;
    return (int16_t)rounded;
}

static bool in_window(int16_t value, int low, int high)
{
    int magnitude = value < 0 ? -value : value;
    return magnitude >= low && magnitude <= high;
}

int lsm_self_test(lsm6dsox *chip, lsm_self_test_result *result)
{
    if (!chip->address)
        return LSM_ERR_BUS;
    int32_t accel[3] = {0, 0, 0}, gyro[3] = {0, 0, 0};
    chip->configured = false;
    int err = lsm_fifo_reset(chip, false);
    if (!err) err = write_reg(chip, LSM_CTRL2_G, 0);
    if (!err) err = write_reg(chip, LSM_CTRL3_C, LSM_CTRL3_C_BDU_IF_INC);
    if (!err) err = write_reg(chip, LSM_CTRL5_C, 0);
    if (!err) err = write_reg(chip, LSM_CTRL1_XL, ctrl1_xl(SELF_TEST_ACCEL_ODR_CODE,
                                                           SELF_TEST_ACCEL_FS_G));
    if (!err)
        err = self_test_change(chip, LSM_STATUS_XLDA, LSM_OUTX_L_A, LSM_CTRL5_C_ST_XL_POSITIVE,
                               1000000000u / lsm_odr_nominal_mhz(SELF_TEST_ACCEL_ODR_CODE), accel);
    if (!err) err = write_reg(chip, LSM_CTRL1_XL, 0);
    if (!err) err = write_reg(chip, LSM_CTRL2_G, ctrl2_g(SELF_TEST_GYRO_ODR_CODE,
                                                         SELF_TEST_GYRO_FS_DPS));
    if (!err)
        err = self_test_change(chip, LSM_STATUS_GDA, LSM_OUTX_L_G, LSM_CTRL5_C_ST_G_POSITIVE,
                               1000000000u / lsm_odr_nominal_mhz(SELF_TEST_GYRO_ODR_CODE), gyro);
    if (!err) err = write_reg(chip, LSM_CTRL2_G, 0);
    if (err)
        return err;
    result->accel_pass = result->gyro_pass = true;
    for (int axis = 0; axis < 3; axis++) {
        /* +-4 g: 0.122 mg/LSB; +-2000 dps: 70 mdps/LSB (0.07 dps). */
        result->accel_delta_mg[axis] = mean_in_units(accel[axis], 122000);
        result->gyro_delta_dps[axis] = mean_in_units(gyro[axis], 70000);
        result->accel_pass &= in_window(result->accel_delta_mg[axis], LSM_SELF_TEST_ACCEL_MIN_MG,
                                        LSM_SELF_TEST_ACCEL_MAX_MG);
        result->gyro_pass &= in_window(result->gyro_delta_dps[axis], LSM_SELF_TEST_GYRO_MIN_DPS,
                                       LSM_SELF_TEST_GYRO_MAX_DPS);
    }
    lsm_settings settings = chip->settings;
    return lsm_configure(chip, &settings);
}
