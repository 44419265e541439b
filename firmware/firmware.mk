# Firmware build, included by the top-level Makefile.
#
#   make firmware BOARD=host|mps2_an385|microbit|stm32f103|stm32vldiscovery|netduino2|sifive_e|atmega328p [MODEL=models/x.toml]
#   make flash BOARD=stm32f103 [FLASH_TOOL=openocd|st-flash]
#
# The filter (accelnav.*) and the frame code (acnframe.*) of MODEL are
# generated into build/firmware/gen/MODEL_NAME/ first; the board's image goes to
# build/firmware/BOARD/ with a size report (size.txt).
#
# The installed package runs this file on its own (accelnav.hil_sim.targets.firmware):
#   make -f FW_DIR/firmware.mk firmware BOARD=... FW_DIR=... FW_OUT=... FW_GEN=... FW_PREGEN=1
# with the generated C already written to FW_GEN, so that nothing depends on
# the source checkout's layout and every output lands in the folder it names.

BOARD      ?= host
MODEL      ?= models/adxl250_default.toml
FW_DIR     ?= firmware
FW_GEN     ?= build/firmware/gen/$(basename $(notdir $(MODEL)))
FW_OUT     ?= build/firmware/$(BOARD)
# FW_WARN and each part's compiler, flags and memories (one table, read by the codegen report too)
include $(FW_DIR)/parts.mk
FW_INC     := -I$(FW_DIR)/src -I$(FW_DIR)/boards -I$(FW_GEN)
FW_COMMON  := $(wildcard $(FW_DIR)/src/*.c) $(FW_GEN)/accelnav.c $(FW_GEN)/acnframe.c
# the folder of the board's sources: stm32vldiscovery is the stm32f103 port built for QEMU's STM32F100
FW_BOARD_DIR := $(FW_DIR)/boards/$(if $(filter stm32vldiscovery,$(BOARD)),stm32f103,$(BOARD))
FW_HEADERS := $(wildcard $(FW_DIR)/src/*.h $(FW_DIR)/boards/*.h $(FW_BOARD_DIR)/*.h)
ARM_CC     ?= $(PART_CC_mps2_an385)
AVR_CC     ?= $(PART_CC_atmega328p)
# the ATmega328P: flash, and RAM less what the stack needs (measured in simavr: firmware/README.md)
AVR_FLASH  := $(PART_FLASH_atmega328p)
AVR_RAM    := $(PART_RAM_atmega328p)
AVR_STACK  ?= $(PART_STACK_atmega328p)

ifeq ($(BOARD),host)
FW_CC      := $(CC)
FW_CFLAGS  := $(FW_WARN) -O2 -g -I$(FW_DIR)/boards/host
FW_SRCS    := $(FW_DIR)/boards/host/board_host.c
FW_LDFLAGS :=
FW_SIZE    := size
else ifeq ($(BOARD),mps2_an385)
FW_CC      := $(ARM_CC)
FW_CFLAGS  := $(FW_WARN) $(PART_CFLAGS_mps2_an385) -I$(FW_DIR)/boards/mps2_an385
FW_SRCS    := $(FW_DIR)/boards/mps2_an385/board_mps2.c $(FW_DIR)/boards/emu_txq.c $(FW_DIR)/boards/emu_feed.c
# the runtime's startup.c (not ours) casts function pointers to void * in its vector
# table, which -pedantic refuses: it is built with the same flags minus -pedantic
FW_LOOSE   := $(FW_DIR)/boards/mps2_an385/startup.c $(FW_DIR)/boards/semihost_rt.c
FW_LDFLAGS := -nostartfiles --specs=nano.specs -T$(FW_DIR)/boards/mps2_an385/mps2_an385.ld \
              -Wl,--gc-sections -Wl,-Map=$(FW_OUT)/accelnav_fw.map
FW_SIZE    := arm-none-eabi-size
else ifeq ($(BOARD),microbit)
# QEMU's BBC micro:bit: nRF51822, Cortex-M0 (no 32x32->64 multiply: 64-bit products go through libgcc)
FW_CC      := $(ARM_CC)
FW_CFLAGS  := $(FW_WARN) $(PART_CFLAGS_microbit) -I$(FW_DIR)/boards/microbit
FW_SRCS    := $(FW_DIR)/boards/microbit/board_microbit.c $(FW_DIR)/boards/emu_txq.c $(FW_DIR)/boards/emu_feed.c
FW_LOOSE   := $(FW_DIR)/boards/microbit/startup.c $(FW_DIR)/boards/semihost_rt.c
FW_LDFLAGS := -nostartfiles --specs=nano.specs -T$(FW_DIR)/boards/microbit/nrf51822.ld \
              -Wl,--gc-sections -Wl,-Map=$(FW_OUT)/accelnav_fw.map
FW_SIZE    := arm-none-eabi-size
else ifneq ($(filter stm32f103 stm32vldiscovery,$(BOARD)),)
# stm32vldiscovery: the same sources and layout for QEMU's STM32F100 (see board_stm32.c, ACN_STM32_QEMU)
FW_CC      := $(ARM_CC)
FW_CFLAGS  := $(FW_WARN) $(PART_CFLAGS_stm32f103) -I$(FW_DIR)/boards/stm32f103 \
              $(if $(filter stm32vldiscovery,$(BOARD)),-DACN_STM32_QEMU)
FW_SRCS    := $(FW_DIR)/boards/stm32f103/startup_stm32f103.c $(FW_DIR)/boards/stm32f103/board_stm32.c \
              $(FW_DIR)/boards/stm32_rt.c $(if $(filter stm32vldiscovery,$(BOARD)),$(FW_DIR)/boards/emu_feed.c)
FW_LD      := $(if $(filter stm32vldiscovery,$(BOARD)),stm32f100rb_qemu.ld,stm32f103c8.ld)
FW_LDFLAGS := -nostartfiles --specs=nano.specs -L$(FW_DIR)/boards/stm32f103 -T$(FW_DIR)/boards/stm32f103/$(FW_LD) \
              -Wl,--gc-sections -Wl,-Map=$(FW_OUT)/accelnav_fw.map
FW_SIZE    := arm-none-eabi-size
else ifeq ($(BOARD),netduino2)
# QEMU's netduino2 (STM32F205): TIM3 and ADC1 sample, USART1 streams (board_netduino2.c); the
# stm32f103 port's vector table (same IRQ numbers for TIM3 and USART1) and image layout
FW_CC      := $(ARM_CC)
FW_CFLAGS  := $(FW_WARN) $(PART_CFLAGS_stm32f103) -I$(FW_DIR)/boards/netduino2 -DACN_STM32_QEMU
FW_SRCS    := $(FW_DIR)/boards/stm32f103/startup_stm32f103.c $(FW_DIR)/boards/netduino2/board_netduino2.c \
              $(FW_DIR)/boards/stm32_rt.c
FW_LDFLAGS := -nostartfiles --specs=nano.specs -L$(FW_DIR)/boards/stm32f103 -T$(FW_DIR)/boards/netduino2/netduino2.ld \
              -Wl,--gc-sections -Wl,-Map=$(FW_OUT)/accelnav_fw.map
FW_SIZE    := arm-none-eabi-size
else ifeq ($(BOARD),sifive_e)
# QEMU's sifive_e: SiFive FE310 (HiFive1), RV32IMAC without FPU; picolibc for string.h and libgcc's
# multilib for rv32imac/ilp32 (an -march with _zicsr would pick the default multilib: the runtime's
# CSR accesses enable zicsr in their own asm instead)
RV_CC      ?= $(PART_CC_sifive_e)
FW_CC      := $(RV_CC)
FW_CFLAGS  := $(FW_WARN) $(PART_CFLAGS_sifive_e) -I$(FW_DIR)/boards/sifive_e
FW_SRCS    := $(FW_DIR)/boards/sifive_e/board_sifive_e.c $(FW_DIR)/boards/emu_txq.c $(FW_DIR)/boards/emu_feed.c
FW_LOOSE   := $(FW_DIR)/boards/sifive_e/startup.c $(FW_DIR)/boards/semihost_rt.c
FW_LDFLAGS := -nostartfiles -T$(FW_DIR)/boards/sifive_e/sifive_e.ld \
              -Wl,--gc-sections -Wl,-Map=$(FW_OUT)/accelnav_fw.map
FW_SIZE    := $(PART_SIZE_sifive_e)
else ifeq ($(BOARD),atmega328p)
# Arduino Uno's ATmega328P (8-bit AVR, 16-bit int), run in simavr. Linked against generous memory
# regions so that a build too big still links and the size check below can say what it needs.
FW_CC      := $(AVR_CC)
FW_CFLAGS  := $(FW_WARN) $(PART_CFLAGS_atmega328p)
FW_SRCS    := $(FW_DIR)/boards/atmega328p/board_atmega328p.c
FW_LDFLAGS := -Wl,--gc-sections -Wl,-Map=$(FW_OUT)/accelnav_fw.map \
              -Wl,--defsym=__TEXT_REGION_LENGTH__=0x40000 -Wl,--defsym=__DATA_REGION_LENGTH__=0xff00
FW_SIZE    := avr-size
else
$(error BOARD=$(BOARD): accepted: host, mps2_an385, microbit, stm32f103, stm32vldiscovery, netduino2, sifive_e, atmega328p)
endif

FW_ELF := $(FW_OUT)/accelnav_fw$(if $(filter host,$(BOARD)),,.elf)
# which model the image in FW_OUT was built for: a different MODEL rebuilds it
FW_STAMP := $(FW_OUT)/.model

.PHONY: firmware firmware-gen flash FORCE
FORCE:

$(FW_STAMP): FORCE
	@mkdir -p $(FW_OUT)
	@echo '$(MODEL)' | cmp -s - $@ || echo '$(MODEL)' > $@

firmware: $(FW_ELF)
	@$(FW_SIZE) $(FW_ELF) | tee $(FW_OUT)/size.txt

firmware-gen: $(FW_GEN)/acnframe.h

# FW_PREGEN: the caller wrote the generated C to FW_GEN itself (the installed package does)
ifndef FW_PREGEN
$(FW_GEN)/acnframe.h $(FW_GEN)/acnframe.c $(FW_GEN)/accelnav.c: $(MODEL) $(wildcard codegen/*.py codegen/csrc/*.h) | $(STAMP)
	$(PY) -m accelnav codegen $(MODEL) --out $(FW_GEN)
	@touch $(FW_GEN)/acnframe.h
endif

FW_LOOSE_OBJ := $(patsubst %.c,$(FW_OUT)/%.o,$(notdir $(FW_LOOSE)))

$(FW_OUT)/%.o: $(FW_BOARD_DIR)/%.c $(FW_HEADERS)
	@mkdir -p $(FW_OUT)
	$(FW_CC) $(filter-out -pedantic,$(FW_CFLAGS)) -I$(FW_DIR)/boards -c $< -o $@

# the runtime the emulated boards share (semihost_rt.c): inline asm with register variables, as startup.c
$(FW_OUT)/%.o: $(FW_DIR)/boards/%.c $(FW_HEADERS)
	@mkdir -p $(FW_OUT)
	$(FW_CC) $(filter-out -pedantic,$(FW_CFLAGS)) -I$(FW_DIR)/boards -c $< -o $@

$(FW_ELF): $(FW_COMMON) $(FW_SRCS) $(FW_LOOSE_OBJ) $(FW_HEADERS) $(wildcard $(FW_BOARD_DIR)/*.ld) $(FW_GEN)/acnframe.h $(FW_STAMP)
	@mkdir -p $(FW_OUT)
	$(FW_CC) $(FW_CFLAGS) $(FW_INC) $(FW_COMMON) $(FW_SRCS) $(FW_LOOSE_OBJ) $(FW_LDFLAGS) -o $@
ifneq ($(filter stm32f103 stm32vldiscovery,$(BOARD)),)
	arm-none-eabi-objcopy -O binary $@ $(FW_OUT)/accelnav_fw.bin
	arm-none-eabi-objcopy -O ihex $@ $(FW_OUT)/accelnav_fw.hex
endif
ifeq ($(BOARD),atmega328p)
	@avr-size -A $@ | awk '/^\.text|^\.data|^\.bss/ {s[$$1] = $$2} END { \
	    flash = s[".text"] + s[".data"]; ram = s[".data"] + s[".bss"]; \
	    if (flash > $(AVR_FLASH) || ram + $(AVR_STACK) > $(AVR_RAM)) { \
	        printf "BOARD=atmega328p: this model needs %d B flash and %d B RAM + %d B stack; the ATmega328P has $(AVR_FLASH) B flash and $(AVR_RAM) B RAM\n", \
	            flash, ram, $(AVR_STACK) > "/dev/stderr"; exit 1 } }' || { rm -f $@; exit 1; }
	avr-objcopy -O ihex -R .eeprom $@ $(FW_OUT)/accelnav_fw.hex
endif

# Not run here (no board attached); with an ST-Link on SWD:
#   openocd: make flash BOARD=stm32f103
#   st-flash: make flash BOARD=stm32f103 FLASH_TOOL=st-flash
FLASH_TOOL ?= openocd
flash: firmware
ifneq ($(BOARD),stm32f103)
	$(error make flash: BOARD=stm32f103 only; mps2_an385 runs in qemu-system-arm (see firmware/README.md))
endif
ifeq ($(FLASH_TOOL),st-flash)
	st-flash --reset write $(FW_OUT)/accelnav_fw.bin 0x08000000
else
	openocd -f interface/stlink.cfg -f target/stm32f1x.cfg \
	    -c "program $(FW_ELF) verify reset exit"
endif
