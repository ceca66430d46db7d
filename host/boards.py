"""The AVR boards an Arduino library is built for and checked against: each one's FQBN, room and core, as the
IDE's boards.txt gives them (tests/test_arduino.py holds them against the installed one)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Board:
    """An AVR board the IDE offers for the manifests' architectures=avr, as its boards.txt gives it."""
    fqbn: str
    flash: int  # bytes a sketch may take (the bootloader's excluded): upload.maximum_size
    ram: int  # upload.maximum_data_size
    label: str  # as a sentence names it
    mcu: str = "atmega328p"  # build.mcu
    ram_start: int = 0x800100  # the linker's address of the core's first RAM byte
    regions: tuple[int, int] = (32768, 2048)  # text and data regions in avr-gcc's device spec
    emulated: bool = True  # the simavr board runs its core (hil/sketch.py), so its stack is measured
    # flash its Arduino core adds to ReadPose beyond the Uno's (measured: the same sketch built for both), so that
    # a build checked on one board tells another's
    core_flash: int = 0

    def flash_of(self, flash: int, built: "Board") -> int:
        """About the flash a build of ``flash`` B for ``built`` takes on this board (its core's share taken)."""
        return flash - built.core_flash + self.core_flash


BOARDS = {
    "uno": Board("arduino:avr:uno", 32256, 2048, "Uno"),
    # both bootloader options of the IDE's Nano take 30,720 B; the build is the same
    "nano": Board("arduino:avr:nano:cpu=atmega328", 30720, 2048, "Nano"),
    # the ATmega32U4's Serial is USB: its core is about 2.2 kB more
    "leonardo": Board("arduino:avr:leonardo", 28672, 2560, "Leonardo", "atmega32u4", regions=(32768, 2560),
                      emulated=False, core_flash=2200),
    "micro": Board("arduino:avr:micro", 28672, 2560, "Micro", "atmega32u4", regions=(32768, 2560), emulated=False,
                   core_flash=2200),
    "mega": Board("arduino:avr:mega:cpu=atmega2560", 253952, 8192, "Mega 2560", "atmega2560", 0x800200,
                  (262144, 8192), core_flash=400),
}
