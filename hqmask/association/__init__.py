"""Multi-view ID association: per-view segment maps in, view-consistent object IDs out.

Both methods take one (H, W) int32 segment map a view (0 = no segment, 1..n local segment
numbers that mean nothing across views) and return one (H, W) uint8 map a view whose IDs
1..K (K <= 255) name the same object in every view.
"""

from hqmask.association.common import compact_ids
from hqmask.association.flow import associate_flow
from hqmask.association.tracks import associate_tracks

__all__ = ["associate_flow", "associate_tracks", "compact_ids"]
