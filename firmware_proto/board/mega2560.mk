# Cross build for the Arduino Mega 2560 with Debian's gcc-avr + avr-libc (included by Makefile).
#   make cross [PROFILE=platform6|platform3|servo8] [DEVICE_NAME=...]   build, print flash and RAM
#   make flash PORT=/dev/ttyACM0                                       upload with avrdude

AVR_CC ?= avr-gcc
AVR_SIZE ?= avr-size
AVR_OBJCOPY ?= avr-objcopy
MCU ?= atmega2560
DEVICE_NAME ?= $(PROFILE)
AVR_BUILD := $(BUILD)/avr-$(PROFILE)
AVR_CFLAGS := -mmcu=$(MCU) -DF_CPU=16000000UL -Os -std=c99 -Wall -Wextra -Werror -pedantic -Wshadow -Wconversion \
	-ffunction-sections -fdata-sections -Isrc -DFW_PROFILE='"$(PROFILE)"' -DFW_DEVICE_NAME='"$(DEVICE_NAME)"'
AVR_LDFLAGS := -mmcu=$(MCU) -Wl,--gc-sections
AVR_CORE_OBJS := $(patsubst src/%.c,$(AVR_BUILD)/%.o,$(CORE) src/fw.c)

# flash = .text + .data, static RAM = .data + .bss (avr-size's Berkeley columns)
AVR_REPORT = $(AVR_SIZE) $(1) | awk -v what="$(2)" 'NR > 1 { t += $$1; d += $$2; b += $$3 } \
	END { printf "%-44s flash %6d B  static RAM %5d B\n", what ":", t + d, d + b }'

cross: $(AVR_BUILD)/firmware.hex $(AVR_BUILD)/core.elf
	@$(call AVR_REPORT,$(AVR_BUILD)/core.elf,core + float/libm + stub HAL ($(MCU)))
	@$(call AVR_REPORT,$(AVR_BUILD)/firmware.elf,firmware $(PROFILE) for the Mega 2560)

$(AVR_BUILD)/%.o: src/%.c $(HEADERS)
	@mkdir -p $(AVR_BUILD)
	$(AVR_CC) $(AVR_CFLAGS) -c $< -o $@
$(AVR_BUILD)/board.o: board/mega2560.c $(HEADERS)
	@mkdir -p $(AVR_BUILD)
	$(AVR_CC) $(AVR_CFLAGS) -c $< -o $@
$(AVR_BUILD)/hal_stub.o: board/hal_stub.c $(HEADERS)
	@mkdir -p $(AVR_BUILD)
	$(AVR_CC) $(AVR_CFLAGS) -c $< -o $@
$(AVR_BUILD)/firmware.elf: $(AVR_CORE_OBJS) $(AVR_BUILD)/board.o
	$(AVR_CC) $(AVR_LDFLAGS) $^ -o $@ -lm
$(AVR_BUILD)/core.elf: $(AVR_CORE_OBJS) $(AVR_BUILD)/hal_stub.o
	$(AVR_CC) $(AVR_LDFLAGS) $^ -o $@ -lm
$(AVR_BUILD)/firmware.hex: $(AVR_BUILD)/firmware.elf
	$(AVR_OBJCOPY) -O ihex -R .eeprom $< $@

# The Mega's stk500v2 bootloader ("wiring" in avrdude); the board resets when the port opens.
flash: $(AVR_BUILD)/firmware.hex
	avrdude -p $(MCU) -c wiring -P $(PORT) -b 115200 -D -U flash:w:$<:i

# The control step's cost on the MCU, measured in simavr (apt install simavr).
$(AVR_BUILD)/step_bench.elf: board/step_bench.c $(AVR_CORE_OBJS)
	$(AVR_CC) $(AVR_CFLAGS) $(AVR_LDFLAGS) $< $(filter-out $(AVR_BUILD)/fw.o,$(AVR_CORE_OBJS)) -o $@ -lm
avr-step-bench: $(AVR_BUILD)/step_bench.elf
	simavr -m $(MCU) -f 16000000 $<
