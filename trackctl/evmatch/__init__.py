"""EV-Matching (dissertation §3.2): match electronic IDs (phones) to visual IDs (people in video)
with EID set splitting, vague zones, VID filtering and matching refining; a local (pandas) and an
Apache Spark engine; the EDP baseline."""

from trackctl.evmatch.data import EData, VStore, load_e, load_ground_truth
from trackctl.evmatch.engines import LocalEngine, SparkEngine, make_engine
from trackctl.evmatch.matcher import MatchOutcome, MatchParams, match_edp, match_ss
from trackctl.evmatch.pipeline import MATCHES_TOPIC, Algorithm, EvMatchConfig, match_log, run
from trackctl.logs.messages import MetricReport
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.processing.base import ProcessorInfo, Progress

__all__ = [
    "PROCESSOR",
    "MATCHES_TOPIC",
    "Algorithm",
    "EData",
    "EvMatchConfig",
    "EvMatchProcessor",
    "LocalEngine",
    "MatchOutcome",
    "MatchParams",
    "SparkEngine",
    "VStore",
    "load_e",
    "load_ground_truth",
    "make_engine",
    "match_edp",
    "match_log",
    "match_ss",
    "run",
]


class EvMatchProcessor:
    """The ``ev-match`` processor (registry entry of :func:`run`)."""

    name = "ev-match"

    def __init__(self, config: EvMatchConfig | None = None) -> None:
        self.config = config or EvMatchConfig()

    def run(
        self, reader: LogReader, writer: LogWriter, progress: Progress | None = None
    ) -> MetricReport:
        return run(reader, writer, self.config, progress)


PROCESSOR = ProcessorInfo(
    name="ev-match",
    description="EV-Matching: EIDs matched to VIDs by EID set splitting (§3.2)",
    factory=EvMatchProcessor,
)
"""Registry entry (entry point ``trackctl.processors``)."""
