/* The magnetometer beside the LSM6DSOX (magnetometer.h says where each register fact is from). */
#include "magnetometer.h"

#include <stddef.h>

static const uint32_t LIS3MDL_RATES_MHZ[] = {10000u, 20000u, 40000u, 80000u};
static const uint8_t LIS3MDL_DO[] = {0x4u, 0x5u, 0x6u, 0x7u}; /* CTRL_REG1 DO[4:2] */
static const uint32_t LIS2MDL_RATES_MHZ[] = {10000u, 20000u, 50000u, 100000u};
static const uint8_t LIS2MDL_ODR[] = {0x0u, 0x1u, 0x2u, 0x3u}; /* CFG_REG_A ODR[3:2] */

void mag_init(magnetometer *mag, const fw_platform *bus)
{
    mag->bus = bus;
    mag->chip = MAG_CHIP_NONE;
    mag->address = 0;
    mag->who_am_i = 0;
    mag->odr_mhz = 0;
    mag->configured = false;
}

static int read_byte(magnetometer *mag, uint8_t address, uint8_t reg, uint8_t *value)
{
    const fw_platform *p = mag->bus;
    return p->i2c_read(p->ctx, address, reg, value, 1) ? MAG_ERR_BUS : MAG_OK;
}

int mag_probe(magnetometer *mag)
{
    static const struct { uint8_t chip, address, reg, value; } candidates[] = {
        {MAG_CHIP_LIS3MDL, LIS3MDL_ADDRESS_SA1_LOW, LIS3MDL_WHO_AM_I, LIS3MDL_WHO_AM_I_VALUE},
        {MAG_CHIP_LIS3MDL, LIS3MDL_ADDRESS_SA1_HIGH, LIS3MDL_WHO_AM_I, LIS3MDL_WHO_AM_I_VALUE},
        {MAG_CHIP_LIS2MDL, LIS2MDL_ADDRESS, LIS2MDL_WHO_AM_I, LIS2MDL_WHO_AM_I_VALUE},
    };
    for (size_t i = 0; i < sizeof candidates / sizeof candidates[0]; i++) {
        uint8_t value = 0;
        if (read_byte(mag, candidates[i].address, candidates[i].reg, &value) == MAG_OK &&
            value == candidates[i].value) {
            mag->chip = candidates[i].chip;
            mag->address = candidates[i].address;
            mag->who_am_i = value;
            return MAG_OK;
        }
    }
    mag->chip = MAG_CHIP_NONE;
    return MAG_ERR_NOT_FOUND;
}

uint32_t mag_rate_mhz(uint8_t chip, uint32_t accel_odr_mhz)
{
    const uint32_t *rates = chip == MAG_CHIP_LIS2MDL ? LIS2MDL_RATES_MHZ : LIS3MDL_RATES_MHZ;
    uint32_t rate = rates[0];
    for (unsigned i = 0; i < 4u; i++)
        if (rates[i] <= accel_odr_mhz)
            rate = rates[i];
    return chip == MAG_CHIP_NONE ? 0u : rate;
}

static unsigned rate_index(uint8_t chip, uint32_t odr_mhz)
{
    const uint32_t *rates = chip == MAG_CHIP_LIS2MDL ? LIS2MDL_RATES_MHZ : LIS3MDL_RATES_MHZ;
    for (unsigned i = 0; i < 4u; i++)
        if (rates[i] == odr_mhz)
            return i;
    return 0;
}

unsigned mag_sequence(uint8_t chip, uint32_t odr_mhz, mag_register_write *out)
{
    unsigned i = rate_index(chip, odr_mhz), n = 0;
    if (chip == MAG_CHIP_LIS3MDL) {
        out[n++] = (mag_register_write){LIS3MDL_CTRL_REG1,
                                        (uint8_t)(LIS3MDL_CTRL_REG1_OM_UHP | LIS3MDL_DO[i] << 2)};
        out[n++] = (mag_register_write){LIS3MDL_CTRL_REG2, LIS3MDL_CTRL_REG2_FS_4_GAUSS};
        out[n++] = (mag_register_write){LIS3MDL_CTRL_REG4, LIS3MDL_CTRL_REG4_OMZ_UHP};
        out[n++] = (mag_register_write){LIS3MDL_CTRL_REG5, LIS3MDL_CTRL_REG5_BDU};
        out[n++] = (mag_register_write){LIS3MDL_CTRL_REG3, LIS3MDL_CTRL_REG3_CONTINUOUS};
    } else if (chip == MAG_CHIP_LIS2MDL) {
        out[n++] = (mag_register_write){LIS2MDL_CFG_REG_B,
                                        LIS2MDL_CFG_REG_B_OFF_CANC | LIS2MDL_CFG_REG_B_LPF};
        out[n++] = (mag_register_write){LIS2MDL_CFG_REG_C, LIS2MDL_CFG_REG_C_BDU};
        /* Last: MD = 00 starts the continuous conversions at the chosen rate. */
        out[n++] = (mag_register_write){LIS2MDL_CFG_REG_A,
                                        (uint8_t)(LIS2MDL_CFG_REG_A_COMP_TEMP_EN |
                                                  LIS2MDL_ODR[i] << 2)};
    }
    return n;
}

int mag_configure(magnetometer *mag, uint32_t accel_odr_mhz)
{
    const fw_platform *p = mag->bus;
    mag->configured = false;
    if (mag->chip == MAG_CHIP_NONE)
        return MAG_ERR_NOT_FOUND;
    uint8_t reset_reg = mag->chip == MAG_CHIP_LIS3MDL ? LIS3MDL_CTRL_REG2 : LIS2MDL_CFG_REG_A;
    uint8_t reset = mag->chip == MAG_CHIP_LIS3MDL ? LIS3MDL_CTRL_REG2_SOFT_RST
                                                  : LIS2MDL_CFG_REG_A_SOFT_RST;
    if (p->i2c_write(p->ctx, mag->address, reset_reg, &reset, 1))
        return MAG_ERR_BUS;
    p->delay_us(p->ctx, MAG_RESET_US);
    uint32_t odr = mag_rate_mhz(mag->chip, accel_odr_mhz);
    mag_register_write sequence[MAG_SEQUENCE_LENGTH];
    unsigned n = mag_sequence(mag->chip, odr, sequence);
    for (unsigned i = 0; i < n; i++)
        if (p->i2c_write(p->ctx, mag->address, sequence[i].reg, &sequence[i].value, 1))
            return MAG_ERR_BUS;
    for (unsigned i = 0; i < n; i++) {
        uint8_t value = 0;
        if (read_byte(mag, mag->address, sequence[i].reg, &value))
            return MAG_ERR_BUS;
        if (value != sequence[i].value)
            return MAG_ERR_READBACK;
    }
    mag->odr_mhz = odr;
    mag->configured = true;
    return MAG_OK;
}

int mag_read(magnetometer *mag, int16_t xyz[3], bool *ready, bool *overrun)
{
    const fw_platform *p = mag->bus;
    uint8_t data[7];
    uint8_t reg = mag->chip == MAG_CHIP_LIS3MDL
        ? (uint8_t)(LIS3MDL_STATUS_REG | LIS3MDL_AUTO_INCREMENT) : LIS2MDL_STATUS_REG;
    if (p->i2c_read(p->ctx, mag->address, reg, data, sizeof data))
        return MAG_ERR_BUS;
    *ready = (data[0] & MAG_STATUS_ZYXDA) != 0;
    *overrun = (data[0] & MAG_STATUS_ZYXOR) != 0;
    for (int axis = 0; axis < 3; axis++)
        xyz[axis] = (int16_t)(data[1 + 2 * axis] | (data[2 + 2 * axis] << 8));
    return MAG_OK;
}

uint16_t mag_range_ut(uint8_t chip)
{
    return chip == MAG_CHIP_LIS2MDL ? 4915u : 400u; /* +-49.152 gauss; +-4 gauss */
}

uint32_t mag_pt_per_lsb(uint8_t chip)
{
    /* LIS2MDL 1.5 mgauss/LSB = 150000 pT; LIS3MDL 1e8 pT / 6842 LSB/gauss = 14615.6 pT. */
    return chip == MAG_CHIP_LIS2MDL ? 150000u : 14616u;
}

uint8_t mag_mode(uint8_t chip)
{
    return chip == MAG_CHIP_LIS2MDL ? MAG_MODE_HIGH_RESOLUTION : MAG_MODE_ULTRA_HIGH_PERFORMANCE;
}

const char *mag_chip_name(uint8_t chip)
{
    return chip == MAG_CHIP_LIS2MDL ? "LIS2MDL" : chip == MAG_CHIP_LIS3MDL ? "LIS3MDL" : "none";
}
