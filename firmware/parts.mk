# The parts the firmware is built for: memories (datasheet figures), usual clock, compiler and the
# flags it compiles every source with. One table for two readers: firmware.mk includes it (the
# build's flags, the ATmega328P's size check) and accelnav.codegen.targets parses it (the report of
# `accelnav codegen --report --target PART`), so the two cannot disagree on a number.
#
# Keep every line `NAME := value`, literal (no $(...)): the Python side reads them with a regex.
# PART_<FIELD>_<part>, FIELD one of NAME ALIASES FLASH RAM MHZ CC SIZE CFLAGS, and STACK where the RAM the
# stack needs was measured (the fit check keeps it free).

# flags of every firmware source, every part
FW_WARN := -std=c99 -Wall -Wextra -Werror -pedantic

# ATmega328P datasheet (DS40002061): 32 KB flash, 2 KB SRAM, 20 MHz max; an Uno runs it at 16 MHz
PART_NAME_atmega328p    := ATmega328P (Arduino Uno; 8-bit AVR, 16-bit int)
PART_ALIASES_atmega328p := uno
PART_FLASH_atmega328p   := 32768
PART_RAM_atmega328p     := 2048
PART_MHZ_atmega328p     := 16
PART_CC_atmega328p      := avr-gcc
PART_SIZE_atmega328p    := avr-size
PART_CFLAGS_atmega328p  := -mmcu=atmega328p -DF_CPU=16000000UL -Os -ffunction-sections -fdata-sections -g
# the firmware's deepest stack in simavr, with margin (firmware/README.md)
PART_STACK_atmega328p   := 768

# FE310-G000 manual: 16 KiB DTIM (data RAM), code from off-chip SPI flash; the HiFive1's 16 MiB part
# leaves 12 MiB from 0x20400000 above its boot loader (sifive_e.ld); 320 MHz on the HiFive1
PART_NAME_sifive_e    := SiFive FE310 (HiFive1; RV32IMAC, no FPU)
PART_ALIASES_sifive_e := fe310
PART_FLASH_sifive_e   := 12582912
PART_RAM_sifive_e     := 16384
PART_MHZ_sifive_e     := 320
PART_CC_sifive_e      := riscv64-unknown-elf-gcc
PART_SIZE_sifive_e    := riscv64-unknown-elf-size
PART_CFLAGS_sifive_e  := -march=rv32imac -mabi=ilp32 -Os -ffunction-sections -fdata-sections -ffreestanding -g --specs=picolibc.specs

# ARM AN385 (MPS2 FPGA image of a Cortex-M3): 4 MB ZBT SSRAM for code, 4 MB for data, 25 MHz
PART_NAME_mps2_an385    := Cortex-M3 (ARM MPS2 AN385 FPGA image)
PART_ALIASES_mps2_an385 := cortex-m3
PART_FLASH_mps2_an385   := 4194304
PART_RAM_mps2_an385     := 4194304
PART_MHZ_mps2_an385     := 25
PART_CC_mps2_an385      := arm-none-eabi-gcc
PART_SIZE_mps2_an385    := arm-none-eabi-size
PART_CFLAGS_mps2_an385  := -mcpu=cortex-m3 -mthumb -Os -ffunction-sections -fdata-sections -ffreestanding -g

# nRF51822-QFAA product specification: 256 kB flash, 16 kB RAM, Cortex-M0 at 16 MHz (BBC micro:bit v1)
PART_NAME_microbit    := nRF51822 (BBC micro:bit; Cortex-M0)
PART_ALIASES_microbit := nrf51
PART_FLASH_microbit   := 262144
PART_RAM_microbit     := 16384
PART_MHZ_microbit     := 16
PART_CC_microbit      := arm-none-eabi-gcc
PART_SIZE_microbit    := arm-none-eabi-size
PART_CFLAGS_microbit  := -mcpu=cortex-m0 -mthumb -Os -ffunction-sections -fdata-sections -ffreestanding -g -masm-syntax-unified

# STM32F103x8 datasheet (DS5319): 64 KB flash, 20 KB SRAM, 72 MHz (the blue pill)
PART_NAME_stm32f103    := STM32F103C8 (blue pill; Cortex-M3)
PART_ALIASES_stm32f103 :=
PART_FLASH_stm32f103   := 65536
PART_RAM_stm32f103     := 20480
PART_MHZ_stm32f103     := 72
PART_CC_stm32f103      := arm-none-eabi-gcc
PART_SIZE_stm32f103    := arm-none-eabi-size
PART_CFLAGS_stm32f103  := -mcpu=cortex-m3 -mthumb -Os -ffunction-sections -fdata-sections -ffreestanding -g
