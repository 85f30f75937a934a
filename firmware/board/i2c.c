/* I2C1 master, polling (RM0385 "Inter-integrated circuit interface", master mode).
 *
 * A transfer longer than 255 bytes is cut into NBYTES chunks with RELOAD: the peripheral
 * stops the clock at the end of each chunk (TCR) until NBYTES is written again. Every wait is
 * bounded by one deadline per transfer: bytes x 50 us (a byte takes 22.5 us at 400 kHz) plus a
 * margin. A NACK leaves the bus clean (the hardware sends STOP); anything else - bus error,
 * arbitration lost, timeout - recovers the bus: nine clocks by hand, a STOP, and a software
 * reset of the peripheral. */
#include "i2c.h"

#include <stdbool.h>

#include "clock.h"
#include "stm32f7.h"

#define PIN_SCL 8u /* PB8 = I2C1_SCL, AF4 (Arduino D15) */
#define PIN_SDA 9u /* PB9 = I2C1_SDA, AF4 (Arduino D14) */
#define AF_I2C1 4u
#define PINS_MASK ((1u << PIN_SCL) | (1u << PIN_SDA))

/* RM0385 "Examples of timings settings for fI2CCLK = 16 MHz", Fast-mode 400 kHz:
 * PRESC 1 -> tPRESC = 2 / 16 MHz = 125 ns; SCLL 9 -> 10 x 125 = 1250 ns low; SCLH 3 -> 500 ns
 * high (plus the synchronisation and rise times: ~2.5 us a bit); SDADEL 2 -> 250 ns data hold;
 * SCLDEL 3 -> 500 ns data setup. */
#define TIMINGR_PRESC 1u
#define TIMINGR_SCLDEL 3u
#define TIMINGR_SDADEL 2u
#define TIMINGR_SCLH 3u
#define TIMINGR_SCLL 9u
#define TIMINGR_400KHZ_HSI16                                                                      \
    ((TIMINGR_PRESC << 28) | (TIMINGR_SCLDEL << 20) | (TIMINGR_SDADEL << 16) |                     \
     (TIMINGR_SCLH << 8) | TIMINGR_SCLL)
_Static_assert(TIMINGR_400KHZ_HSI16 == 0x10320309u, "RM0385 Fast-mode timing at 16 MHz");

#define NBYTES_MAX 255u
#define US_PER_BYTE_BUDGET 50u      /* 9 bit times at 400 kHz = 22.5 us, doubled */
#define TRANSFER_MARGIN_US 2000u    /* clock stretching, the repeated START, the STOP */
#define BUS_FREE_TIMEOUT_US 1000u   /* another transfer's STOP still on its way */
#define STOP_TIMEOUT_US 500u        /* STOP after a NACK: a few bit times */
#define RECOVERY_HALF_BIT_US 5u     /* bit-banged recovery clock: 100 kHz */
#define RECOVERY_CLOCKS 9u          /* a slave mid-byte needs at most 8 clocks + the ACK */
#define SCL_RELEASE_TIMEOUT_US 1000u /* a slave may stretch SCL */
#define ERROR_FLAGS (I2C_ISR_BERR | I2C_ISR_ARLO | I2C_ISR_OVR)

static uint32_t s_start_us;
static uint32_t s_budget_us;
static uint32_t s_recoveries;

static bool line_high(unsigned pin) { return ((GPIOB->IDR >> pin) & 1u) != 0u; }

static void pins_to_i2c(void)
{
    gpio_af(GPIOB, PIN_SCL, AF_I2C1);
    gpio_af(GPIOB, PIN_SDA, AF_I2C1);
    gpio_field2(&GPIOB->MODER, PIN_SCL, GPIO_MODE_AF); /* the peripheral drives the pins */
    gpio_field2(&GPIOB->MODER, PIN_SDA, GPIO_MODE_AF);
}

static void pins_to_gpio(void)
{
    GPIOB->BSRR = PINS_MASK;         /* output latches high = open drain released */
    gpio_field2(&GPIOB->MODER, PIN_SCL, GPIO_MODE_OUTPUT); /* software drives the pins */
    gpio_field2(&GPIOB->MODER, PIN_SDA, GPIO_MODE_OUTPUT);
}

/* Software reset (PE low for 3+ APB cycles clears the state machine and the flags), then the
 * timing, then enable: analog filter on, no digital filter, clock stretching allowed (required
 * in master mode), no interrupts. */
static void peripheral_reset(void)
{
    I2C1->CR1 &= ~I2C_CR1_PE;
    for (int i = 0; i < 3; i++) {
        (void)I2C1->CR1;             /* each read takes at least one APB1 cycle */
    }
    I2C1->TIMINGR = TIMINGR_400KHZ_HSI16; /* writable only while PE = 0 */
    I2C1->CR2 = 0u;
    I2C1->CR1 = I2C_CR1_PE;
}

static void bus_recover(void)
{
    s_recoveries++;
    I2C1->CR1 &= ~I2C_CR1_PE;        /* the peripheral lets go of the pins */
    pins_to_gpio();
    /* Clock until the slave releases SDA (it was in the middle of a byte or its ACK). */
    for (unsigned i = 0; i < RECOVERY_CLOCKS && !line_high(PIN_SDA); i++) {
        GPIOB->BSRR = 1u << (PIN_SCL + 16u); /* SCL low */
        board_delay_us(RECOVERY_HALF_BIT_US);
        GPIOB->BSRR = 1u << PIN_SCL;         /* SCL released */
        uint32_t t0 = board_micros();
        while (!line_high(PIN_SCL) && board_micros() - t0 < SCL_RELEASE_TIMEOUT_US) {
        }
        board_delay_us(RECOVERY_HALF_BIT_US);
    }
    /* STOP: SDA rises while SCL is high. */
    GPIOB->BSRR = 1u << (PIN_SCL + 16u);     /* SCL low */
    board_delay_us(RECOVERY_HALF_BIT_US);
    GPIOB->BSRR = 1u << (PIN_SDA + 16u);     /* SDA low */
    board_delay_us(RECOVERY_HALF_BIT_US);
    GPIOB->BSRR = 1u << PIN_SCL;             /* SCL high */
    board_delay_us(RECOVERY_HALF_BIT_US);
    GPIOB->BSRR = 1u << PIN_SDA;             /* SDA high: STOP */
    board_delay_us(RECOVERY_HALF_BIT_US);
    pins_to_i2c();
    peripheral_reset();
}

void i2c_init(void)
{
    RCC->AHB1ENR |= RCC_AHB1ENR_GPIOBEN;     /* clock port B */
    RCC->DCKCFGR2 = (RCC->DCKCFGR2 & ~RCC_DCKCFGR2_I2C1SEL_MASK) |
                    RCC_DCKCFGR2_I2C1SEL_HSI; /* I2C1 kernel clock = HSI 16 MHz */
    RCC->APB1ENR |= RCC_APB1_I2C1;           /* clock the I2C1 registers */
    RCC->APB1RSTR |= RCC_APB1_I2C1;          /* pulse its reset */
    RCC->APB1RSTR &= ~RCC_APB1_I2C1;
    (void)RCC->APB1ENR;

    GPIOB->OTYPER |= PINS_MASK;              /* open drain, as I2C requires */
    gpio_field2(&GPIOB->OSPEEDR, PIN_SCL, GPIO_SPEED_HIGH);
    gpio_field2(&GPIOB->OSPEEDR, PIN_SDA, GPIO_SPEED_HIGH);
    gpio_field2(&GPIOB->PUPDR, PIN_SCL, GPIO_PULL_UP); /* ~40 kOhm: a fallback only, the */
    gpio_field2(&GPIOB->PUPDR, PIN_SDA, GPIO_PULL_UP); /* sensor boards have their own */
    GPIOB->BSRR = PINS_MASK;                 /* latches high for when recovery takes the pins */
    pins_to_i2c();
    peripheral_reset();

    board_delay_us(10u);                     /* let the pull-ups lift the lines */
    if ((I2C1->ISR & I2C_ISR_BUSY) || !line_high(PIN_SDA) || !line_high(PIN_SCL)) {
        bus_recover();                       /* a slave still holds the bus from before reset */
    }
}

/* Wait for `flag`, reporting a NACK, a bus error or the transfer deadline instead. */
static int wait_flag(uint32_t flag)
{
    for (;;) {
        uint32_t isr = I2C1->ISR;
        if (isr & I2C_ISR_NACKF) {
            return I2C_ERR_NACK;
        }
        if (isr & ERROR_FLAGS) {
            return I2C_ERR_BUS;
        }
        if (isr & flag) {
            return I2C_OK;
        }
        if (board_micros() - s_start_us > s_budget_us) {
            return I2C_ERR_TIMEOUT;
        }
    }
}

static int transfer_begin(size_t wire_bytes)
{
    uint32_t t0 = board_micros();
    while ((I2C1->ISR & I2C_ISR_BUSY) && board_micros() - t0 < BUS_FREE_TIMEOUT_US) {
    }
    if (I2C1->ISR & I2C_ISR_BUSY) {
        bus_recover();
        if (!line_high(PIN_SDA) || !line_high(PIN_SCL)) {
            return I2C_ERR_BUS;              /* still held low: try again next time */
        }
    }
    I2C1->ICR = I2C_ICR_ALL;                 /* no stale flags */
    s_start_us = board_micros();
    s_budget_us = (uint32_t)wire_bytes * US_PER_BYTE_BUDGET + TRANSFER_MARGIN_US;
    return I2C_OK;
}

static int transfer_end(int err)
{
    if (err == I2C_OK) {
        I2C1->ICR = I2C_ICR_ALL;             /* STOPF (and nothing else) */
        I2C1->CR2 = 0u;
        return I2C_OK;
    }
    if (err == I2C_ERR_NACK) {
        /* In master mode the hardware sends STOP after a NACK; wait for it, then clean up. */
        uint32_t t0 = board_micros();
        while (!(I2C1->ISR & I2C_ISR_STOPF) && board_micros() - t0 < STOP_TIMEOUT_US) {
        }
        if (I2C1->ISR & I2C_ISR_STOPF) {
            I2C1->ICR = I2C_ICR_ALL;         /* NACKF, STOPF */
            I2C1->ISR = I2C_ISR_TXE;         /* flush a byte left in TXDR */
            I2C1->CR2 = 0u;
            return err;
        }
    }
    bus_recover();
    return err;
}

/* NBYTES/RELOAD/AUTOEND for the `left` bytes still to go. */
static uint32_t chunk_bits(size_t left, bool autoend)
{
    if (left > NBYTES_MAX) {
        return (NBYTES_MAX << I2C_CR2_NBYTES_POS) | I2C_CR2_RELOAD;
    }
    return ((uint32_t)left << I2C_CR2_NBYTES_POS) | (autoend ? I2C_CR2_AUTOEND : 0u);
}

static size_t chunk_len(size_t left) { return left > NBYTES_MAX ? NBYTES_MAX : left; }

/* START, address+W, reg, data; then STOP (autoend) or TC, ready for a repeated START. */
static int send(uint32_t sadd, uint8_t reg, const uint8_t *data, size_t n, bool autoend)
{
    size_t total = n + 1u, done = 0u, in_chunk = chunk_len(total);
    I2C1->CR2 = sadd | chunk_bits(total, autoend) | I2C_CR2_START; /* write direction */
    while (done < total) {
        int err;
        if (in_chunk == 0u) {
            if ((err = wait_flag(I2C_ISR_TCR)) != I2C_OK) {
                return err;
            }
            I2C1->CR2 = sadd | chunk_bits(total - done, autoend); /* new NBYTES clears TCR */
            in_chunk = chunk_len(total - done);
        }
        if ((err = wait_flag(I2C_ISR_TXIS)) != I2C_OK) {
            return err;
        }
        I2C1->TXDR = done == 0u ? reg : data[done - 1u];
        done++;
        in_chunk--;
    }
    return I2C_OK;
}

/* (Repeated) START, address+R, n bytes, NACK on the last, STOP. */
static int receive(uint32_t sadd, uint8_t *data, size_t n)
{
    size_t done = 0u, in_chunk = chunk_len(n);
    sadd |= I2C_CR2_RD_WRN;
    I2C1->CR2 = sadd | chunk_bits(n, true) | I2C_CR2_START;
    while (done < n) {
        int err;
        if (in_chunk == 0u) {
            if ((err = wait_flag(I2C_ISR_TCR)) != I2C_OK) {
                return err;
            }
            I2C1->CR2 = sadd | chunk_bits(n - done, true); /* new NBYTES clears TCR */
            in_chunk = chunk_len(n - done);
        }
        if ((err = wait_flag(I2C_ISR_RXNE)) != I2C_OK) {
            return err;
        }
        data[done++] = (uint8_t)I2C1->RXDR; /* reading RXDR clears RXNE */
        in_chunk--;
    }
    return I2C_OK;
}

int i2c_write_regs(uint8_t addr7, uint8_t reg, const uint8_t *data, size_t n)
{
    if (n > 0u && data == NULL) {
        return I2C_ERR_ARG;
    }
    int err = transfer_begin(n + 2u);        /* address, register, data */
    if (err != I2C_OK) {
        return err;
    }
    uint32_t sadd = (uint32_t)(addr7 & 0x7Fu) << (I2C_CR2_SADD_POS + 1u);
    err = send(sadd, reg, data, n, true);
    if (err == I2C_OK) {
        err = wait_flag(I2C_ISR_STOPF);
    }
    return transfer_end(err);
}

int i2c_read_regs(uint8_t addr7, uint8_t reg, uint8_t *data, size_t n)
{
    if (n == 0u || data == NULL) {
        return I2C_ERR_ARG;
    }
    int err = transfer_begin(n + 3u);        /* two addresses, register, data */
    if (err != I2C_OK) {
        return err;
    }
    uint32_t sadd = (uint32_t)(addr7 & 0x7Fu) << (I2C_CR2_SADD_POS + 1u);
    err = send(sadd, reg, NULL, 0u, false);
    if (err == I2C_OK) {
        err = wait_flag(I2C_ISR_TC);         /* register sent, SCL held: repeated START next */
    }
    if (err == I2C_OK) {
        err = receive(sadd, data, n);
    }
    if (err == I2C_OK) {
        err = wait_flag(I2C_ISR_STOPF);
    }
    return transfer_end(err);
}

uint32_t i2c_recoveries(void) { return s_recoveries; }
