"""``python -m worker``: run one descriptor-queue consumer (settings from ``SHAPES_*``).

``--queue enroll`` (the default) describes enrolled meshes at a lower CPU priority;
``--queue query`` describes the meshes clients are waiting for.
"""

from __future__ import annotations

import argparse

from .jobs.queue import run_consumer
from .jobs.settings import QUEUES, QueueSettings


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m worker", description=__doc__)
    parser.add_argument(
        "--threads",
        type=int,
        default=1,
        help="tasks run at once in this process (default 1; start more processes instead)",
    )
    parser.add_argument(
        "--queue", choices=QUEUES, default="enroll", help="which queue to consume (default enroll)"
    )
    args = parser.parse_args(argv)
    run_consumer(QueueSettings(), workers=args.threads, queue=args.queue)


if __name__ == "__main__":
    main()
