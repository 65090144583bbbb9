"""The simulated camera: what one camera sees of the simulated machine and its two ChArUco
boards (:mod:`.scene`), rendered through a distorting lens (:mod:`.optics`,
:mod:`.render`) and an imperfect image chain (:mod:`.imaging`); calibration views
(:mod:`.views`); whole camera session folders (:mod:`.session`)."""
