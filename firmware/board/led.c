#include "led.h"

#include <stdint.h>

#include "stm32f7.h"

static const unsigned led_pins[] = {[LED_GREEN] = 0u, [LED_BLUE] = 7u, [LED_RED] = 14u};

static void led_configure(unsigned pin)
{
    /* Push-pull (OTYPER bit 0), no pull, low speed (reset values): only the mode changes. */
    GPIOB->BSRR = 1u << (pin + 16u); /* start dark: BSRR upper half resets the pin */
    gpio_field2(&GPIOB->MODER, pin, GPIO_MODE_OUTPUT);
}

void led_init(void)
{
    RCC->AHB1ENR |= RCC_AHB1ENR_GPIOBEN; /* clock port B */
    (void)RCC->AHB1ENR;                  /* read back: the enable takes effect before use */
    for (unsigned i = 0; i < sizeof led_pins / sizeof led_pins[0]; i++) {
        led_configure(led_pins[i]);
    }
}

void led_set(led_id led, bool on)
{
    /* BSRR: the lower half sets, the upper half resets, atomically (no read-modify-write). */
    unsigned pin = led_pins[led];
    GPIOB->BSRR = on ? (1u << pin) : (1u << (pin + 16u));
}

void led_fault_on(void)
{
    RCC->AHB1ENR |= RCC_AHB1ENR_GPIOBEN; /* the fault may come before led_init */
    (void)RCC->AHB1ENR;
    gpio_field2(&GPIOB->MODER, led_pins[LED_RED], GPIO_MODE_OUTPUT);
    GPIOB->BSRR = 1u << led_pins[LED_RED]; /* red on */
}
