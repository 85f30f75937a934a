/* NUCLEO-F746ZG user LEDs (UM1974 "LEDs"): LD1 green PB0, LD2 blue PB7, LD3 red PB14, each lit
 * when its pin is driven high. */
#ifndef BOARD_LED_H
#define BOARD_LED_H

#include <stdbool.h>

typedef enum led_id { LED_GREEN, LED_BLUE, LED_RED } led_id;

void led_init(void);
void led_set(led_id led, bool on);

/* Red LED on without relying on led_init (used from the fault handler). */
void led_fault_on(void);

#endif
