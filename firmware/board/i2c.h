/* I2C1 master on PB8 (SCL) / PB9 (SDA), 400 kHz Fast-mode, polling. */
#ifndef BOARD_I2C_H
#define BOARD_I2C_H

#include <stddef.h>
#include <stdint.h>

#define I2C_BUS_HZ 400000u

enum {
    I2C_OK = 0,
    I2C_ERR_NACK = 1,    /* address or data not acknowledged */
    I2C_ERR_BUS = 2,     /* bus error or arbitration lost (misplaced START/STOP, noise) */
    I2C_ERR_TIMEOUT = 3, /* a flag never came: SCL held low, bus stuck */
    I2C_ERR_ARG = 4,     /* zero-length read or a NULL buffer */
};

/* Needs clock_init first (timeouts use board_micros). Recovers a bus left BUSY. */
void i2c_init(void);

/* START, address+W, reg, data[0..n-1], STOP. */
int i2c_write_regs(uint8_t addr7, uint8_t reg, const uint8_t *data, size_t n);
/* START, address+W, reg, repeated START, address+R, n bytes, STOP (n may exceed 255). */
int i2c_read_regs(uint8_t addr7, uint8_t reg, uint8_t *data, size_t n);

/* Times the bus had to be recovered (nine clocks + STOP + peripheral reset). */
uint32_t i2c_recoveries(void);

#endif
