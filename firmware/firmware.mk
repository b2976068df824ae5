# The trigger box's firmware and its simulator (docs/trigger-box.md); included by the top Makefile.
#   make firmware        target/firmware/trigger-box.{elf,hex} (avr-gcc) and target/firmware/box-sim
#   make firmware-check  run the firmware in box-sim and drive it over its pty (selfcheck.py)
FW_OUT := target/firmware
FW_SRC := firmware/trigger-box/main.c firmware/trigger-box/proto.c
FW_HDR := firmware/trigger-box/config.h firmware/trigger-box/proto.h
AVR_CC ?= avr-gcc
AVR_OBJCOPY ?= avr-objcopy
AVR_SIZE ?= avr-size
FW_CFLAGS := -mmcu=atmega328p -DF_CPU=16000000UL -Os -std=gnu99 -Wall -Wextra -Werror \
	-ffunction-sections -fdata-sections -Wl,--gc-sections
SIM_CC ?= cc
# Debian's simavr.pc needs libelf.pc (libelf-dev), which nothing here needs otherwise: plain flags.
SIMAVR_INC ?= /usr/include/simavr
SIM_CFLAGS := -O2 -std=gnu99 -Wall -Wextra -Werror -I$(SIMAVR_INC)
SIM_LIBS := -lsimavr -lutil

.PHONY: firmware firmware-build firmware-check

firmware: setup-libs
	@$(MAKE) --no-print-directory firmware-build

firmware-build: $(FW_OUT)/trigger-box.elf $(FW_OUT)/trigger-box.hex $(FW_OUT)/box-sim $(FW_OUT)/proto-test
	$(FW_OUT)/proto-test

$(FW_OUT)/trigger-box.elf: $(FW_SRC) $(FW_HDR) firmware/firmware.mk
	@mkdir -p $(FW_OUT)
	$(AVR_CC) $(FW_CFLAGS) -o $@ $(FW_SRC)
	@$(AVR_SIZE) $@

$(FW_OUT)/trigger-box.hex: $(FW_OUT)/trigger-box.elf
	$(AVR_OBJCOPY) -O ihex -R .eeprom $< $@

$(FW_OUT)/box-sim: firmware/box-sim/box_sim.c firmware/firmware.mk
	@mkdir -p $(FW_OUT)
	$(SIM_CC) $(SIM_CFLAGS) -o $@ $< $(SIM_LIBS)

# The lexer and the line formatting, built for this machine and tested (run by firmware-build).
$(FW_OUT)/proto-test: firmware/box-sim/proto_test.c firmware/trigger-box/proto.c firmware/trigger-box/proto.h
	@mkdir -p $(FW_OUT)
	$(SIM_CC) -O1 -std=gnu99 -Wall -Wextra -Werror -Ifirmware/trigger-box -o $@ \
		firmware/box-sim/proto_test.c firmware/trigger-box/proto.c

firmware-check: firmware
	python3 firmware/box-sim/selfcheck.py --box-sim $(FW_OUT)/box-sim --elf $(FW_OUT)/trigger-box.elf \
		--out $(FW_OUT)/selfcheck
