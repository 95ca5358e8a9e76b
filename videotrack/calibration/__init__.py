"""Camera calibration from views of a checkerboard, ChArUco board or ArUco grid: board config
and detection (:mod:`.boards`, :mod:`.detect`), bundle adjustment (:mod:`.bundle`), refinement
from the animal (:mod:`.refine`), report (:mod:`.report`), any camera file (:mod:`.formats`)
and rendered test views (:mod:`.synthetic`)."""
