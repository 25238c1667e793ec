"""The Foxglove layout for a run (built with the foxglove SDK's layout types): a 3D panel of the
world (vehicles, trails, readings, plume, a time-dependent plume's filaments or puffs), a map of
the vehicles' fixes and one concentration plot per vehicle (reported and true)."""

from __future__ import annotations

import json
from collections.abc import Sequence

import foxglove.layouts as fl

from recorder.foxglove.channels import (
    PLUME_STATE_TOPIC,
    PLUME_TOPIC,
    READINGS_TOPIC,
    TRAILS_TOPIC,
    VEHICLES_TOPIC,
    WORLD_FRAME,
    concentration_topic,
    location_topic,
)


def layout(vehicle_ids: Sequence[str]) -> fl.Layout:
    scene_topics: dict[str, fl.BaseRendererTopicSettings] = {
        topic: fl.BaseRendererSceneUpdateTopicSettings(visible=True)
        for topic in (
            VEHICLES_TOPIC,
            TRAILS_TOPIC,
            READINGS_TOPIC,
            PLUME_TOPIC,
            PLUME_STATE_TOPIC,
        )
    }
    three_d = fl.ThreeDeePanel(
        title="World (ENU)",
        config=fl.ThreeDeeConfig(
            fixed_frame=WORLD_FRAME, follow_tf=WORLD_FRAME, topics=scene_topics
        ),
    )
    first = location_topic(vehicle_ids[0]) if vehicle_ids else None
    map_panel = fl.MapPanel(title="Vehicles", config=fl.MapConfig(follow_topic=first))
    plots = [
        fl.SplitItem(
            content=fl.PlotPanel(
                title=f"{vid} concentration (g/m³)",
                config=fl.PlotConfig(
                    paths=[
                        fl.PlotSeries(
                            value=f"{concentration_topic(vid)}.reported_g_m3", label="reported"
                        ),
                        fl.PlotSeries(value=f"{concentration_topic(vid)}.true_g_m3", label="true"),
                    ],
                    show_legend=True,
                ),
            )
        )
        for vid in vehicle_ids
    ]
    side = fl.SplitContainer(
        direction="column",
        items=[fl.SplitItem(proportion=max(1, len(plots)) / 2, content=map_panel), *plots],
    )
    return fl.Layout(
        content=fl.SplitContainer(
            direction="row",
            items=[
                fl.SplitItem(proportion=3, content=three_d),
                fl.SplitItem(proportion=2, content=side),
            ],
        )
    )


def layout_json(vehicle_ids: Sequence[str]) -> str:
    """The layout as JSON (the SDK's layout format), pretty-printed."""
    return json.dumps(json.loads(layout(vehicle_ids).to_json()), indent=2) + "\n"
