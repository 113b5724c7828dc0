"""`dem ensemble --profile P`'s check before it touches the results folder: when P submits to
Slurm, a controller must answer (demkit.ensemble.slurm_preflight). Exit 0: go on; exit 2: the
reason is on stderr and nothing was written."""
import sys

from demkit.ensemble import slurm_preflight, uses_slurm


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        sys.stderr.write("usage: python3 -m demkit.slurm_preflight PROFILE\n")
        return 2
    profile = argv[0]
    why = slurm_preflight() if uses_slurm(profile) else None
    if why:
        sys.stderr.write(f"dem ensemble: --profile {profile}: {why}; nothing was written\n")
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
