/* The LSM6DSOX over an I2C bus: probe, the configuration sequence, FIFO access, self-test.
 *
 * The configuration sequence is the contract shared with the Python register driver
 * (drivers/lsm6dsox_direct/registers.py: configuration_sequence) and checked against
 * tests/vectors/lsm6dsox_config.json by the host tests:
 *
 *   1 CTRL3_C   0x12 <- 0x01  SW_RESET, then poll until bit 0 reads 0
 *   2 CTRL3_C   0x12 <- 0x44  BDU | IF_INC
 *   3 CTRL9_XL  0x18 <- 0xE2  I3C disabled (DEN bits kept)
 *   4 FIFO_CTRL3 0x09 <- BDR_GY << 4 | BDR_XL   (both at the ODR)
 *   5 FIFO_CTRL4 0x0A <- 0xA6  timestamp every 8th slot, temperature at 12.5 Hz, continuous
 *   6 CTRL10_C  0x19 <- 0x20  TIMESTAMP_EN
 *   7 CTRL1_XL  0x10 <- ODR << 4 | FS_XL << 2
 *   8 CTRL2_G   0x11 <- ODR << 4 | FS_G << 1
 */
#ifndef FW_LSM6DSOX_H
#define FW_LSM6DSOX_H

#include <stdbool.h>
#include <stdint.h>

#include "platform.h"

#define LSM6DSOX_WHO_AM_I_VALUE 0x6Cu
#define LSM6DSOX_ADDRESS_SA0_LOW 0x6Au
#define LSM6DSOX_ADDRESS_SA0_HIGH 0x6Bu

/* Registers. */
enum {
    LSM_FIFO_CTRL3 = 0x09,
    LSM_FIFO_CTRL4 = 0x0A,
    LSM_WHO_AM_I = 0x0F,
    LSM_CTRL1_XL = 0x10,
    LSM_CTRL2_G = 0x11,
    LSM_CTRL3_C = 0x12,
    LSM_CTRL5_C = 0x14,
    LSM_CTRL9_XL = 0x18,
    LSM_CTRL10_C = 0x19,
    LSM_STATUS_REG = 0x1E,
    LSM_OUT_TEMP_L = 0x20,
    LSM_OUTX_L_G = 0x22,
    LSM_OUTX_L_A = 0x28,
    LSM_FIFO_STATUS1 = 0x3A,
    LSM_FIFO_STATUS2 = 0x3B,
    LSM_TIMESTAMP0 = 0x40,
    LSM_INTERNAL_FREQ_FINE = 0x63,
    LSM_FIFO_DATA_OUT_TAG = 0x78,
};

/* Bits and values. */
#define LSM_CTRL3_C_SW_RESET 0x01u
#define LSM_CTRL3_C_BDU_IF_INC 0x44u
#define LSM_CTRL9_XL_I3C_DISABLED 0xE2u
#define LSM_CTRL10_C_TIMESTAMP_EN 0x20u
#define LSM_FIFO_CTRL4_BATCHING 0xA0u /* DEC_TS_BATCH = 8, ODR_T_BATCH = 12.5 Hz */
#define LSM_FIFO_MODE_BYPASS 0x00u
#define LSM_FIFO_MODE_CONTINUOUS 0x06u
#define LSM_FIFO_STATUS2_DIFF_HIGH 0x03u
#define LSM_FIFO_STATUS2_OVR_LATCHED 0x08u
#define LSM_FIFO_STATUS2_OVR_IA 0x40u
#define LSM_STATUS_XLDA 0x01u
#define LSM_STATUS_GDA 0x02u
#define LSM_CTRL5_C_ST_XL_POSITIVE 0x01u
#define LSM_CTRL5_C_ST_G_POSITIVE 0x04u

/* FIFO words: a tag byte (TAG_SENSOR[7:3], TAG_CNT[2:1], TAG_PARITY[0]) and 6 data bytes. */
#define LSM_FIFO_WORD_BYTES 7u
enum { LSM_TAG_GYRO = 0x01, LSM_TAG_ACCEL = 0x02, LSM_TAG_TEMPERATURE = 0x03,
       LSM_TAG_TIMESTAMP = 0x04, LSM_TAG_CFG_CHANGE = 0x05 };
#define LSM_TIMESTAMP_DECIMATION 8u /* a timestamp word every 8th slot */

#define LSM_ODR_CODE_MIN 1u
#define LSM_ODR_CODE_MAX 10u

/* Self-test (ST's procedure; windows from HARDWARE.md, LSM6DSO datasheet). */
#define LSM_SELF_TEST_ACCEL_MIN_MG 50
#define LSM_SELF_TEST_ACCEL_MAX_MG 1700
#define LSM_SELF_TEST_GYRO_MIN_DPS 150 /* at +-2000 dps */
#define LSM_SELF_TEST_GYRO_MAX_DPS 700

/* Errors: 0 is success. */
enum {
    LSM_OK = 0,
    LSM_ERR_BUS = -1,        /* no ACK, timeout: nothing answering */
    LSM_ERR_WHO_AM_I = -2,   /* something answered, but not an LSM6DSOX */
    LSM_ERR_RESET = -3,      /* SW_RESET did not finish */
    LSM_ERR_READBACK = -4,   /* a configuration register did not keep its value */
    LSM_ERR_NO_DATA = -5,    /* self-test: no new sample in time */
};

/* Output data rate of an ODR code (1..10) in millihertz before the clock trim: the rate the
 * chip really runs at, 6666.67 Hz / 2^(10 - code) (13021 for "12.5 Hz", 104167 for "104 Hz");
 * 0 for other codes. */
uint32_t lsm_odr_nominal_mhz(uint8_t odr_code);
/* The datasheet's label of an ODR code in millihertz (12500, 104000, ...), for people. */
uint32_t lsm_odr_label_mhz(uint8_t odr_code);
/* Samples of the accelerometer (`gyro` false) or gyroscope to discard after the ODR is set:
 * the turn-on transient's settling figures plus two. */
uint16_t lsm_turn_on_discard(uint8_t odr_code, bool gyro);
/* FS_XL / FS_G field codes; -1 for a full scale the chip does not have. */
int lsm_fs_xl_code(uint8_t accel_fs_g);
int lsm_fs_g_code(uint16_t gyro_fs_dps);

typedef struct lsm_settings {
    uint8_t odr_code;     /* 1..10 */
    uint8_t accel_fs_g;   /* 2, 4, 8, 16 */
    uint16_t gyro_fs_dps; /* 125, 250, 500, 1000, 2000 */
} lsm_settings;

typedef struct lsm_write {
    uint8_t reg;
    uint8_t value;
} lsm_write;

#define LSM_SEQUENCE_LENGTH 8u

/* Fill `out` with the configuration sequence for valid `settings`; false when invalid. */
bool lsm_configuration_sequence(const lsm_settings *settings, lsm_write out[LSM_SEQUENCE_LENGTH]);

typedef struct lsm6dsox {
    const fw_platform *platform;
    uint8_t address;   /* 0 until probed */
    uint8_t who_am_i;  /* last WHO_AM_I read (0x00 when nothing answered) */
    int8_t freq_fine;  /* INTERNAL_FREQ_FINE: clock trim in steps of 0.15 % */
    bool configured;
    uint32_t configured_us; /* platform micros() when the ODR was last set (transient start) */
    lsm_settings settings;
} lsm6dsox;

void lsm_init(lsm6dsox *chip, const fw_platform *platform);

/* Find the chip at 0x6A, then 0x6B; read WHO_AM_I. LSM_OK, LSM_ERR_BUS or LSM_ERR_WHO_AM_I. */
int lsm_probe(lsm6dsox *chip);

/* Look at one address only: LSM_OK (an LSM6DSOX answers), LSM_ERR_BUS or LSM_ERR_WHO_AM_I.
 * The address is kept either way (0 when nothing answered). */
int lsm_probe_at(lsm6dsox *chip, uint8_t address);

/* Run the configuration sequence, check it by reading the registers back, read the trim.
 * Leaves the sensors on and the FIFO filling in continuous mode. */
int lsm_configure(lsm6dsox *chip, const lsm_settings *settings);

/* Empty the FIFO (bypass) and, when `restart`, fill it again in continuous mode. */
int lsm_fifo_reset(lsm6dsox *chip, bool restart);

/* FIFO_STATUS1/2 in one read: unread words and the overrun flags. */
int lsm_fifo_status(lsm6dsox *chip, uint16_t *words, bool *overrun);

/* Read `words` FIFO words (7 bytes each) in one burst into `out`. */
int lsm_fifo_read(lsm6dsox *chip, uint8_t *out, uint16_t words);

/* OUT_TEMP_L/H: degC = raw / 256 + 25. */
int lsm_read_temperature(lsm6dsox *chip, int16_t *raw);
/* The chip's timestamp counter now (TIMESTAMP0..3, ticks of lsm_tick_ns): the time a
 * magnetometer's field sample is stamped with (docs/protocol.md, MAG_SAMPLES). */
int lsm_read_timestamp(lsm6dsox *chip, uint32_t *ticks);

/* Output data rate and timestamp tick of the trimmed clock (docs/protocol.md section 5). */
uint32_t lsm_odr_mhz(const lsm6dsox *chip);
uint32_t lsm_tick_ns(const lsm6dsox *chip);

typedef struct lsm_self_test_result {
    bool accel_pass;
    bool gyro_pass;
    int16_t accel_delta_mg[3];  /* self-test on minus off, per axis */
    int16_t gyro_delta_dps[3];
} lsm_self_test_result;

/* ST's self-test: accelerometer at 52 Hz, +-4 g, gyroscope at 208 Hz, +-2000 dps; 100 ms to
 * settle, one sample dropped, five averaged, with and without the positive self-test force.
 * Takes about half a second; the sensor must lie still. Leaves the chip reconfigured with
 * `chip->settings` (FIFO in continuous mode, as after lsm_configure). */
int lsm_self_test(lsm6dsox *chip, lsm_self_test_result *result);

#endif
