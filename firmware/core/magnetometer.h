/* The magnetometer beside the LSM6DSOX: an LIS3MDL or an LIS2MDL on the same I2C bus, read
 * directly by the board (docs/protocol.md, "A magnetometer beside the sensor").
 *
 * Register facts (checked against ST's datasheets and register headers):
 *   LIS3MDL (datasheet DocID024204; STMicroelectronics/lis3mdl-pid lis3mdl_reg.h)
 *     I2C 0x1C (SA1 low) or 0x1E (SA1 high); WHO_AM_I 0x0F reads 0x3D
 *     CTRL_REG1 0x20: TEMP_EN[7] OM[6:5] DO[4:2] FAST_ODR[1] ST[0]; OM = 11 ultra-high-
 *       performance on X and Y; DO 100/101/110/111 = 10/20/40/80 Hz (lis3mdl_om_t
 *       LIS3MDL_UHP_10Hz = 0x38 ... LIS3MDL_UHP_80Hz = 0x3E, the field above ST)
 *     CTRL_REG2 0x21: FS[6:5] = 00 +-4 gauss (6842 LSB/gauss), REBOOT[3], SOFT_RST[2]
 *     CTRL_REG3 0x22: LP[5] = 0, SIM[2], MD[1:0] = 00 continuous conversion
 *     CTRL_REG4 0x23: OMZ[3:2] = 11 ultra-high-performance on Z, BLE[1] = 0 (LSB first)
 *     CTRL_REG5 0x24: FAST_READ[7] = 0, BDU[6] = 1 (block data update)
 *     STATUS_REG 0x27: ZYXDA[3] new X, Y, Z; ZYXOR[7] overrun; OUT_X_L..OUT_Z_H 0x28..0x2D
 *     A multi-byte I2C read asserts the sub-address MSB (auto-increment), as ST's examples.
 *   LIS2MDL (ST's datasheet; STMicroelectronics/lis2mdl-pid lis2mdl_reg.h)
 *     I2C 0x1E; WHO_AM_I 0x4F reads 0x40
 *     CFG_REG_A 0x60: COMP_TEMP_EN[7] = 1, REBOOT[6], SOFT_RST[5], LP[4] = 0 (high
 *       resolution), ODR[3:2] 00/01/10/11 = 10/20/50/100 Hz, MD[1:0] = 00 continuous
 *     CFG_REG_B 0x61: OFF_CANC_ONE_SHOT[4], INT_on_DataOFF[3], Set_FREQ[2] = 0,
 *       OFF_CANC[1] = 1 (offset cancellation every ODR: set_rst = 01,
 *       LIS2MDL_SENS_OFF_CANC_EVERY_ODR), LPF[0] = 1 (bandwidth ODR/4: less noise)
 *     CFG_REG_C 0x62: BDU[4] = 1, BLE[3] = 0
 *     STATUS_REG 0x67: Zyxda[3]; OUTX_L_REG..OUTZ_H_REG 0x68..0x6D; 1.5 mgauss/LSB
 *
 * Its best low-noise setting for a rate: the LIS3MDL in ultra-high-performance on all axes,
 * the LIS2MDL in high resolution with offset cancellation and the narrower filter; the rate
 * is the chip's fastest not above the accelerometer's. */
#ifndef FW_MAGNETOMETER_H
#define FW_MAGNETOMETER_H

#include <stdbool.h>
#include <stdint.h>

#include "platform.h"

enum { MAG_CHIP_NONE = 0, MAG_CHIP_LIS3MDL = 1, MAG_CHIP_LIS2MDL = 2 };
enum { MAG_MODE_ULTRA_HIGH_PERFORMANCE = 3, MAG_MODE_HIGH_RESOLUTION = 4 };

#define LIS3MDL_ADDRESS_SA1_LOW 0x1Cu
#define LIS3MDL_ADDRESS_SA1_HIGH 0x1Eu
#define LIS3MDL_WHO_AM_I 0x0Fu
#define LIS3MDL_WHO_AM_I_VALUE 0x3Du
#define LIS3MDL_CTRL_REG1 0x20u
#define LIS3MDL_CTRL_REG2 0x21u
#define LIS3MDL_CTRL_REG3 0x22u
#define LIS3MDL_CTRL_REG4 0x23u
#define LIS3MDL_CTRL_REG5 0x24u
#define LIS3MDL_STATUS_REG 0x27u
#define LIS3MDL_AUTO_INCREMENT 0x80u
#define LIS3MDL_CTRL_REG1_OM_UHP 0x60u
#define LIS3MDL_CTRL_REG2_SOFT_RST 0x04u
#define LIS3MDL_CTRL_REG2_FS_4_GAUSS 0x00u
#define LIS3MDL_CTRL_REG3_CONTINUOUS 0x00u
#define LIS3MDL_CTRL_REG4_OMZ_UHP 0x0Cu
#define LIS3MDL_CTRL_REG5_BDU 0x40u

#define LIS2MDL_ADDRESS 0x1Eu
#define LIS2MDL_WHO_AM_I 0x4Fu
#define LIS2MDL_WHO_AM_I_VALUE 0x40u
#define LIS2MDL_CFG_REG_A 0x60u
#define LIS2MDL_CFG_REG_B 0x61u
#define LIS2MDL_CFG_REG_C 0x62u
#define LIS2MDL_STATUS_REG 0x67u
#define LIS2MDL_CFG_REG_A_COMP_TEMP_EN 0x80u
#define LIS2MDL_CFG_REG_A_SOFT_RST 0x20u
#define LIS2MDL_CFG_REG_B_OFF_CANC 0x02u
#define LIS2MDL_CFG_REG_B_LPF 0x01u
#define LIS2MDL_CFG_REG_C_BDU 0x10u

#define MAG_STATUS_ZYXDA 0x08u
#define MAG_STATUS_ZYXOR 0x80u /* a sample was overwritten before it was read */
#define MAG_RESET_US 5000u /* soft reset and reboot: a few ms (a margin on both datasheets) */
#define MAG_SEQUENCE_LENGTH 5u

enum { MAG_OK = 0, MAG_ERR_BUS = -1, MAG_ERR_NOT_FOUND = -2, MAG_ERR_READBACK = -3 };

typedef struct mag_register_write {
    uint8_t reg;
    uint8_t value;
} mag_register_write;

typedef struct magnetometer {
    const fw_platform *bus;
    uint8_t chip;      /* MAG_CHIP_* */
    uint8_t address;
    uint8_t who_am_i;
    uint32_t odr_mhz;  /* the rate in effect */
    bool configured;
} magnetometer;

void mag_init(magnetometer *mag, const fw_platform *bus);

/* Looks for an LIS3MDL at 0x1C, then 0x1E, then an LIS2MDL at 0x1E. */
int mag_probe(magnetometer *mag);

/* The chip's rate for an accelerometer rate: its fastest not above it, else its slowest. */
uint32_t mag_rate_mhz(uint8_t chip, uint32_t accel_odr_mhz);

/* The register writes that configure the chip at `odr_mhz` (after its soft reset), in
 * order; returns their number (at most MAG_SEQUENCE_LENGTH). */
unsigned mag_sequence(uint8_t chip, uint32_t odr_mhz, mag_register_write *out);

/* Soft reset, then the configuration sequence for the accelerometer's rate, read back. */
int mag_configure(magnetometer *mag, uint32_t accel_odr_mhz);

/* One burst of the status and output registers: `*ready` when ZYXDA says new X, Y, Z,
 * `*overrun` when ZYXOR says one was overwritten unread. */
int mag_read(magnetometer *mag, int16_t xyz[3], bool *ready, bool *overrun);

/* What MAGNETOMETER reports: full scale (+-uT), picotesla per LSB, mode. */
uint16_t mag_range_ut(uint8_t chip);
uint32_t mag_pt_per_lsb(uint8_t chip);
uint8_t mag_mode(uint8_t chip);
const char *mag_chip_name(uint8_t chip);

#endif
