/* Ring buffers shared with USART3_IRQHandler, single producer / single consumer each:
 *   RX: the ISR writes bytes and advances rx_head; the main loop reads and advances rx_tail.
 *   TX: the main loop writes bytes and advances tx_head; the ISR sends and advances tx_tail.
 * Indices run freely (uint32_t, wrapping) and are masked on use, so head - tail is the fill
 * level and the whole ring is usable. Each side publishes its index only after a dmb() (also a
 * compiler barrier) so the data it wrote is visible before the index says it is there. */
#include "uart.h"

#include <stdbool.h>
#include <string.h>

#include "clock.h"
#include "stm32f7.h"
#include "uart_divisor.h"

#define RX_SIZE 2048u  /* ~22 ms of traffic at 921600 baud */
#define TX_SIZE 16384u /* ~180 ms of traffic */
_Static_assert((RX_SIZE & (RX_SIZE - 1u)) == 0 && (TX_SIZE & (TX_SIZE - 1u)) == 0,
               "ring sizes must be powers of two");

#define PIN_TX 8u /* PD8 = USART3_TX, AF7 (datasheet alternate function table) */
#define PIN_RX 9u /* PD9 = USART3_RX, AF7 */
#define AF_USART3 7u
#define UART_IRQ_PRIORITY 5u /* 0 = highest of 16; nothing else uses interrupts */

static uint8_t rx_buf[RX_SIZE];
static uint8_t tx_buf[TX_SIZE];
static volatile uint32_t rx_head, rx_tail, tx_head, tx_tail;
static volatile uart_stats stats;

void uart_init(void)
{
    RCC->AHB1ENR |= RCC_AHB1ENR_GPIODEN; /* clock port D */
    RCC->DCKCFGR2 = (RCC->DCKCFGR2 & ~RCC_DCKCFGR2_USART3SEL_MASK) |
                    RCC_DCKCFGR2_USART3SEL_SYSCLK; /* USART3 kernel clock = SYSCLK (216 MHz) */
    RCC->APB1ENR |= RCC_APB1_USART3;     /* clock the USART3 registers */
    RCC->APB1RSTR |= RCC_APB1_USART3;    /* pulse its reset: known state after a warm restart */
    RCC->APB1RSTR &= ~RCC_APB1_USART3;
    (void)RCC->APB1ENR;

    gpio_af(GPIOD, PIN_TX, AF_USART3);   /* route the pins to USART3 ... */
    gpio_af(GPIOD, PIN_RX, AF_USART3);
    gpio_field2(&GPIOD->OSPEEDR, PIN_TX, GPIO_SPEED_HIGH); /* clean edges at 921600 baud */
    gpio_field2(&GPIOD->PUPDR, PIN_RX, GPIO_PULL_UP); /* idle high if the ST-LINK is absent */
    gpio_field2(&GPIOD->MODER, PIN_TX, GPIO_MODE_AF); /* ... and hand them over */
    gpio_field2(&GPIOD->MODER, PIN_RX, GPIO_MODE_AF);

    /* Oversampling by 16: BRR = f_ck / baud, rounded. 216 MHz / 921600 = 234.375 -> 234 ->
     * 923077 baud, +0.16 %. On the HSI alone (16 MHz, the PLL failed) 16x would be 941 176
     * baud (+2.1 %): uart_divisor_for then picks 8x oversampling, 914 286 baud (-0.8 %). */
    uart_divisor divisor = uart_divisor_for(clock_sysclk_hz(), UART_BAUD);
    USART3->BRR = divisor.brr;
    USART3->CR2 = 0u;                    /* 1 stop bit, no LIN, no clock output */
    USART3->CR3 = USART_CR3_EIE;         /* interrupt on framing/noise/overrun errors too */
    USART3->ICR = USART_ICR_ERRORS;      /* clear any stale error flags */
    rx_head = rx_tail = tx_head = tx_tail = 0u;
    /* 8 data bits (M = 00), no parity; enable TX, RX and the RXNE interrupt, then the USART. */
    USART3->CR1 = (divisor.over8 ? USART_CR1_OVER8 : 0u) | USART_CR1_TE | USART_CR1_RE |
                  USART_CR1_RXNEIE | USART_CR1_UE;

    NVIC_IPR8(IRQ_USART3) = (uint8_t)(UART_IRQ_PRIORITY << NVIC_PRIO_SHIFT);
    NVIC_ISER(IRQ_USART3 / 32u) = 1u << (IRQ_USART3 % 32u); /* enable IRQ 39 in the NVIC */
}

void USART3_IRQHandler(void)
{
    uint32_t isr = USART3->ISR;
    bool bad = false;
    if (isr & (USART_ISR_ORE | USART_ISR_FE | USART_ISR_NE | USART_ISR_PE)) {
        if (isr & USART_ISR_ORE) {
            stats.overruns++;
        }
        if (isr & (USART_ISR_FE | USART_ISR_NE | USART_ISR_PE)) {
            stats.framing_errors++;
            bad = true;
        }
        USART3->ICR = USART_ICR_ERRORS;  /* clear ORE/FE/NE/PE, or ORE would fire forever */
    }
    if (isr & USART_ISR_RXNE) {
        uint8_t byte = (uint8_t)USART3->RDR; /* reading RDR clears RXNE */
        uint32_t head = rx_head;
        if (bad) {
            /* corrupted byte: dropped (the link layer's CRC would reject it anyway) */
        } else if (head - rx_tail < RX_SIZE) {
            rx_buf[head & (RX_SIZE - 1u)] = byte;
            dmb();                       /* byte stored before the index publishes it */
            rx_head = head + 1u;
        } else {
            stats.rx_dropped++;
        }
    }
    if ((USART3->CR1 & USART_CR1_TXEIE) && (isr & USART_ISR_TXE)) {
        uint32_t tail = tx_tail;
        if (tail != tx_head) {
            dmb();                       /* index read before the byte it covers */
            USART3->TDR = tx_buf[tail & (TX_SIZE - 1u)]; /* writing TDR clears TXE */
            tx_tail = tail + 1u;
        } else {
            USART3->CR1 &= ~USART_CR1_TXEIE; /* ring empty: stop the TXE interrupt */
        }
    }
}

size_t uart_read(uint8_t *buf, size_t max)
{
    uint32_t tail = rx_tail;
    uint32_t avail = rx_head - tail;
    dmb();                               /* index read before the bytes it covers */
    size_t n = avail < max ? avail : max;
    for (size_t i = 0; i < n; i++) {
        buf[i] = rx_buf[(tail + i) & (RX_SIZE - 1u)];
    }
    dmb();                               /* bytes read before the slots are handed back */
    rx_tail = tail + (uint32_t)n;
    return n;
}

size_t uart_tx_free(void)
{
    return TX_SIZE - (tx_head - tx_tail);
}

void uart_write(const uint8_t *data, size_t n)
{
    size_t room = uart_tx_free();
    if (n > room) {
        stats.tx_dropped += (uint32_t)(n - room);
        n = room;                        /* contract broken by the caller: keep what fits */
    }
    if (n == 0u) {
        return;
    }
    uint32_t head = tx_head;
    size_t first = TX_SIZE - (head & (TX_SIZE - 1u)); /* bytes before the ring wraps */
    if (first > n) {
        first = n;
    }
    memcpy(&tx_buf[head & (TX_SIZE - 1u)], data, first);
    memcpy(tx_buf, data + first, n - first);
    dmb();                               /* bytes stored before the index publishes them */
    tx_head = head + (uint32_t)n;

    uint32_t primask = irq_save();       /* CR1 is also written by the ISR */
    USART3->CR1 |= USART_CR1_TXEIE;      /* the ISR sends until the ring is empty */
    irq_restore(primask);
}

uart_stats uart_get_stats(void)
{
    uint32_t primask = irq_save();       /* a consistent snapshot */
    uart_stats copy = {stats.overruns, stats.framing_errors, stats.rx_dropped, stats.tx_dropped};
    irq_restore(primask);
    return copy;
}
