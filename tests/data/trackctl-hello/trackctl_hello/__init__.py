"""A minimal third-party trackctl processor: counts the input's messages per topic."""

from __future__ import annotations

from collections import Counter

from trackctl.logs.messages import MetricReport
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.processing import ProcessorInfo, Progress


class HelloProcessor:
    """Reports the number of messages and of topics; writes nothing else."""

    name = "hello"

    def run(
        self, reader: LogReader, writer: LogWriter, progress: Progress | None = None
    ) -> MetricReport:
        counts = Counter(raw.topic for raw in reader.raw())
        return MetricReport(
            t_ns=reader.end_ns or 0,
            processor=self.name,
            metrics={"hello_messages": sum(counts.values()), "hello_topics": len(counts)},
        )


PROCESSOR = ProcessorInfo(
    name="hello", description="Hello: messages and topics of the input", factory=HelloProcessor
)
