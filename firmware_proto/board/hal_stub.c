/* A HAL that does nothing: links the core alone, to measure its flash and RAM on the MCU. */
#include "fw.h"
#include "hal.h"

uint32_t hal_millis(void) { return 0; }
size_t hal_serial_read(uint8_t *buf, size_t cap) { (void)buf; (void)cap; return 0; }
int hal_serial_write(const uint8_t *bytes, size_t n) { (void)bytes; (void)n; return 1; }
int hal_estop_input(void) { return 0; }
int hal_read_feedback(int16_t *measured, uint8_t n) { (void)measured; (void)n; return 0; }
void hal_write_outputs(const device_t *d) { (void)d; }

int main(void)
{
    static fw_t fw;
    fw_init(&fw, &PROFILES[0], "platform6", 0, 0);
    for (;;)
        fw_poll(&fw);
}
