"""Mark symbol versions an ELF executable needs as weak (VER_FLG_WEAK in .gnu.version_r), so that the dynamic
linker only warns where the host's library lacks them; the symbols themselves must then come from elsewhere
(isoc23.c, preloaded). Used by newer_uml.sh on Debian unstable's UML, which needs GLIBC_2.38 for two functions.

    python weak_version.py FILE VERSION [VERSION ...]      prints how many requirements it marked
"""
import struct
import sys

SHT_GNU_VERNEED, VER_FLG_WEAK = 0x6FFFFFFE, 0x2


def weaken(data: bytearray, versions: set) -> int:
    if data[:4] != b"\x7fELF" or data[4] != 2 or data[5] != 1:
        raise ValueError("not a 64-bit little-endian ELF file")
    shoff, = struct.unpack_from("<Q", data, 0x28)
    shentsize, shnum = struct.unpack_from("<HH", data, 0x3A)

    def section(i):       # sh_name, sh_type, sh_flags, sh_addr, sh_offset, sh_size, sh_link, sh_info, ...
        return struct.unpack_from("<IIQQQQIIQQ", data, shoff + i * shentsize)

    marked = 0
    for i in range(shnum):
        _, kind, _, _, offset, _, link, count, _, _ = section(i)
        if kind != SHT_GNU_VERNEED:
            continue
        strings = section(link)[4]
        at = offset
        for _ in range(count):                         # Elf64_Verneed: version, cnt, file, aux, next
            _, aux_count, _, aux, step = struct.unpack_from("<HHIII", data, at)
            entry = at + aux
            for _ in range(aux_count):                 # Elf64_Vernaux: hash, flags, other, name, next
                _, flags, _, name, aux_step = struct.unpack_from("<IHHII", data, entry)
                start = strings + name
                if bytes(data[start:data.index(b"\0", start)]).decode() in versions:
                    struct.pack_into("<H", data, entry + 4, flags | VER_FLG_WEAK)
                    marked += 1
                entry += aux_step
            at += step
    return marked


if __name__ == "__main__":
    path, wanted = sys.argv[1], set(sys.argv[2:])
    with open(path, "rb") as f:
        content = bytearray(f.read())
    n = weaken(content, wanted)
    with open(path, "r+b") as f:
        f.write(content)
    print(n)
