"""The firmware builds: its C unit tests under the sanitizers, and the ARM image for the board.

The ARM build needs Debian's gcc-arm-none-eabi and libnewlib-arm-none-eabi (``.ci/run``
installs them); without them that one test is skipped, saying so. The host build needs only gcc.
"""

from __future__ import annotations

import shutil
import struct
import subprocess
from pathlib import Path

import pytest

FIRMWARE = Path(__file__).resolve().parents[1] / "firmware"
FLASH_ORIGIN, FLASH_BYTES = 0x0800_0000, 1024 * 1024
RAM_ORIGIN, RAM_BYTES = 0x2000_0000, 320 * 1024
USART3_IRQ = 39


def test_c_unit_tests_pass_under_address_and_undefined_behaviour_sanitizers(
        firmware_lib, tmp_path_factory) -> None:
    # firmware_lib ran `make host` into its own folder: the test binary sits beside the library.
    binary = Path(firmware_lib._name).parent / "test_core"
    result = subprocess.run([str(binary)], capture_output=True, text=True, timeout=300,
                            check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    checks, failed = result.stdout.split()[0], result.stdout.split()[2]
    assert int(checks) > 10_000 and failed == "0"


def symbol_address(nm_output: str, name: str) -> int:
    for line in nm_output.splitlines():
        fields = line.split()
        if len(fields) == 3 and fields[2] == name:
            return int(fields[0], 16)
    raise AssertionError(f"no symbol {name}")


NO_ARM_TOOLCHAIN = pytest.mark.skipif(
    shutil.which("arm-none-eabi-gcc") is None,
    reason="no ARM toolchain: apt-get install gcc-arm-none-eabi libnewlib-arm-none-eabi "
           "(.ci/run does)")


@NO_ARM_TOOLCHAIN
def test_arm_image_builds_and_boots_from_its_vector_table(tmp_path) -> None:
    result = subprocess.run(["make", "-C", str(FIRMWARE), f"BUILD={tmp_path}"],
                            capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "flash:" in result.stdout and "RAM:" in result.stdout
    elf, binary = tmp_path / "inclinometer.elf", tmp_path / "inclinometer.bin"
    assert (tmp_path / "inclinometer.hex").read_text().startswith(":")
    image = binary.read_bytes()
    assert 1024 < len(image) < FLASH_BYTES
    # Word 0: the initial stack pointer, inside RAM; word 1: the reset handler, thumb bit set.
    initial_sp, reset = struct.unpack_from("<II", image)
    assert RAM_ORIGIN < initial_sp <= RAM_ORIGIN + RAM_BYTES and initial_sp % 8 == 0
    nm = subprocess.run(["arm-none-eabi-nm", str(elf)], capture_output=True, text=True,
                        check=True).stdout
    assert reset == symbol_address(nm, "Reset_Handler") | 1
    (usart3_vector,) = struct.unpack_from("<I", image, 4 * (16 + USART3_IRQ))
    assert usart3_vector == symbol_address(nm, "USART3_IRQHandler") | 1
    # The core is in the image, and nothing needs an allocator or printf.
    for needed in ("fw_init", "fw_poll", "fw_receive", "lsm_configure", "cobs_encode"):
        symbol_address(nm, needed)
    assert " malloc" not in nm and "printf" not in nm


@NO_ARM_TOOLCHAIN
@pytest.mark.skipif(shutil.which("qemu-system-arm") is None,
                    reason="no QEMU: apt-get install qemu-system-arm (.ci/run does)")
def test_c_unit_tests_pass_on_an_emulated_cortex_m7(tmp_path) -> None:
    """Built by the cross compiler with the firmware's flags: 32-bit size_t, unsigned char."""
    result = subprocess.run(["make", "-C", str(FIRMWARE), "qemu-test", f"BUILD={tmp_path}"],
                            capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    summary = next(line for line in result.stdout.splitlines() if line.endswith(" failed"))
    checks, _, failed, _ = summary.split()
    assert int(checks) > 10_000 and failed == "0"
