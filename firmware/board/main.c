/* NUCLEO-F746ZG board: brings up the hardware, hands the portable core its platform, and runs
 * the main loop (UART bytes in, fw_poll, LEDs, watchdog). */
#include <stdint.h>

#include "clock.h"
#include "firmware.h"
#include "i2c.h"
#include "led.h"
#include "stm32f7.h"
#include "uart.h"

#define BOARD_NAME "NUCLEO-F746ZG"
#define RX_CHUNK 256u
#define RX_CHUNKS_PER_LOOP 16u /* 4 KB: more than the 2 KB ring holds */

/* IWDG: LSI ~32 kHz / 64 = 500 Hz; reload 999 -> 1000 ticks = 2.0 s. The LSI spreads from
 * 17 to 47 kHz over parts and temperature (datasheet), so the timeout is 1.4 to 3.8 s. */
#define IWDG_PRESCALER_DIV64 4u
#define IWDG_RELOAD 999u
#define IWDG_UPDATE_TIMEOUT_US 50000u /* PVU/RVU clear after ~5 LSI periods */

static fw_state fw; /* ~2 KB: static, not on the stack */

/* The watchdog-reset count survives a reset in a section the startup code does not zero; the
 * magic word tells a count from the RAM's random content after a power-on. */
#define NOINIT_MAGIC 0x57444F47u /* "WDOG" */
static struct {
    uint32_t magic;
    uint32_t watchdog_resets;
} noinit __attribute__((section(".noinit")));
static uint8_t s_reset_cause;
static clock_source s_clock_source;

/* Why the MCU started (RCC_CSR), then clear the flags for the next reset. A power-on also sets
 * the pin and brown-out flags, so the order of the checks matters. */
static uint8_t read_reset_cause(void)
{
    uint32_t csr = RCC->CSR;
    RCC->CSR = csr | RCC_CSR_RMVF;
    if (csr & RCC_CSR_IWDGRSTF)
        return LINK_RESET_IWDG;
    if (csr & RCC_CSR_WWDGRSTF)
        return LINK_RESET_WWDG;
    if (csr & RCC_CSR_LPWRRSTF)
        return LINK_RESET_LOW_POWER;
    if (csr & RCC_CSR_PORRSTF)
        return LINK_RESET_POWER_ON;
    if (csr & RCC_CSR_BORRSTF)
        return LINK_RESET_BROWN_OUT;
    if (csr & RCC_CSR_SFTRSTF)
        return LINK_RESET_SOFTWARE;
    if (csr & RCC_CSR_PINRSTF)
        return LINK_RESET_PIN;
    return LINK_RESET_UNKNOWN;
}

static void count_resets(uint8_t cause)
{
    bool power_on = cause == LINK_RESET_POWER_ON || cause == LINK_RESET_BROWN_OUT;
    if (power_on || noinit.magic != NOINIT_MAGIC) {
        noinit.magic = NOINIT_MAGIC;
        noinit.watchdog_resets = 0;
    }
    if (cause == LINK_RESET_IWDG)
        noinit.watchdog_resets++;
}

/* The X-NUCLEO-IKS01A3 routes the DIL24 sensor's INT1 to Arduino A5 = PF10. An LSM6DSOX that
 * sees INT1 high when it resets (at power-up, or at the firmware's SW_RESET) enters I3C mode
 * and stops answering on I2C; the board's level shifter can hold a '1' across an MCU reset.
 * ST's own IKS01A3 example drives the line low before it talks to the sensor. The firmware
 * routes no interrupt to INT1, so the chip keeps the pin low too: no contention. */
#define SENSOR_INT1_PIN 10u /* PF10 */

static void sensor_int1_low(void)
{
    RCC->AHB1ENR |= RCC_AHB1ENR_GPIOFEN;                 /* clock port F */
    (void)RCC->AHB1ENR;
    GPIOF->BSRR = 1u << (SENSOR_INT1_PIN + 16u);         /* latch low first ... */
    gpio_field2(&GPIOF->MODER, SENSOR_INT1_PIN, GPIO_MODE_OUTPUT); /* ... then drive it */
}

static void watchdog_start(void)
{
    DBGMCU_APB1_FZ |= DBGMCU_APB1_FZ_IWDG_STOP; /* stop the count while a debugger halts us */
    IWDG->KR = IWDG_KEY_START;       /* start the watchdog (it cannot be stopped again) */
    IWDG->KR = IWDG_KEY_UNLOCK;      /* allow writes to PR and RLR */
    IWDG->PR = IWDG_PRESCALER_DIV64; /* LSI / 64 */
    IWDG->RLR = IWDG_RELOAD;         /* 1000 ticks */
    uint32_t t0 = board_micros();
    while ((IWDG->SR & IWDG_SR_BUSY) && board_micros() - t0 < IWDG_UPDATE_TIMEOUT_US) {
        /* the new values cross into the LSI domain */
    }
    IWDG->KR = IWDG_KEY_RELOAD;      /* load the counter with the new reload value */
}

void board_watchdog_feed(void)
{
    IWDG->KR = IWDG_KEY_RELOAD;      /* reload the down-counter */
}

/* ---- the platform the core runs on */

static int plat_i2c_write(void *ctx, uint8_t address, uint8_t reg, const uint8_t *data,
                          size_t length)
{
    (void)ctx;
    return i2c_write_regs(address, reg, data, length);
}

static int plat_i2c_read(void *ctx, uint8_t address, uint8_t reg, uint8_t *data, size_t length)
{
    (void)ctx;
    return i2c_read_regs(address, reg, data, length);
}

static uint32_t plat_micros(void *ctx)
{
    (void)ctx;
    return board_micros();
}

static void plat_delay_us(void *ctx, uint32_t us)
{
    (void)ctx;
    board_delay_us(us);
}

static size_t plat_tx_free(void *ctx)
{
    (void)ctx;
    return uart_tx_free();
}

static void plat_tx_write(void *ctx, const uint8_t *data, size_t length)
{
    (void)ctx;
    uart_write(data, length);
}

static void plat_board_health(void *ctx, fw_board_health *health)
{
    (void)ctx;
    uart_stats uart = uart_get_stats();
    health->uart_rx_errors = uart.overruns + uart.framing_errors + uart.rx_dropped;
    health->uart_tx_dropped_bytes = uart.tx_dropped;
    health->i2c_recoveries = i2c_recoveries();
    health->watchdog_resets = noinit.watchdog_resets;
    health->reset_cause = s_reset_cause;
    health->clock_fallback = s_clock_source != CLOCK_HSE_BYPASS_PLL;
}

static const fw_platform platform = {
    .ctx = NULL,
    .i2c_write = plat_i2c_write,
    .i2c_read = plat_i2c_read,
    .micros = plat_micros,
    .delay_us = plat_delay_us,
    .tx_free = plat_tx_free,
    .tx_write = plat_tx_write,
    .board_health = plat_board_health,
};

int main(void)
{
    s_reset_cause = read_reset_cause();
    count_resets(s_reset_cause);
    clock_source source = clock_init();
    s_clock_source = source;
    led_init();
    led_set(LED_BLUE, source != CLOCK_HSE_BYPASS_PLL); /* blue: not on the ST-LINK clock */
    watchdog_start();
    sensor_int1_low();
    uart_init();
    i2c_init();

    fw_identity identity = {
        .name = BOARD_NAME,
        .baud = UART_BAUD,
        .i2c_hz = I2C_BUS_HZ,
    };
    const volatile uint8_t *uid = (const volatile uint8_t *)(uintptr_t)UNIQUE_ID_BASE;
    for (unsigned i = 0; i < UNIQUE_ID_BYTES; i++) {
        identity.unique_id[i] = uid[i]; /* byte by byte, in memory order */
    }
    _Static_assert(sizeof identity.unique_id == UNIQUE_ID_BYTES, "96-bit unique id");

    fw_init(&fw, &platform, &identity);

    static uint8_t rx[RX_CHUNK];
    for (;;) {
        /* Drain what arrived, a chunk at a time, but never loop forever on a flood. */
        for (unsigned i = 0; i < RX_CHUNKS_PER_LOOP; i++) {
            size_t n = uart_read(rx, sizeof rx);
            if (n == 0u) {
                break;
            }
            fw_receive(&fw, rx, n);
        }
        fw_poll(&fw);

        fw_led_mode mode = fw_led_mode_now(&fw);
        led_set(LED_GREEN, fw_led_lit(mode, board_millis()));
        led_set(LED_RED, mode == FW_LED_ERROR);
        board_watchdog_feed();
    }
}
