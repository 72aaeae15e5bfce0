; The robot's initial, naive knowledge base K: four actions over the fluents that
; perception reports. It knows nothing about reachability yet; novelty teaches it.
; `touching` is symmetric: problems list both orderings and every effect on it
; asserts both, so any PDDL tool reads the same meaning.
(define (domain llcps)
    (:requirements :strips :typing :negative-preconditions :equality :action-costs)
    (:types
        item container surface - entity
    )
    (:constants table - surface)
    (:predicates
        (visible ?e - entity)
        (reachable ?e - entity)
        (touching ?a - entity ?b - entity)
        (on ?e - entity ?s - entity)
        (in ?o - entity ?c - entity)
        (holding ?o - entity)
        (near ?a - entity ?b - entity)
    )
    (:functions (total-cost) - number)

    ; push ?o over into ?c. Its controller is push(?o), oriented toward ?c.
    (:action push
        :parameters (?o - item ?c - container)
        :precondition (and (visible ?o) (near ?o ?c) (not (in ?o ?c)))
        :effect (and (in ?o ?c) (not (on ?o table)) (increase (total-cost) 1))
    )

    (:action push_together
        :parameters (?a - entity ?b - entity)
        :precondition (and (visible ?a) (visible ?b) (not (touching ?a ?b)) (not (= ?a ?b)))
        :effect (and (touching ?a ?b) (touching ?b ?a) (increase (total-cost) 1))
    )

    (:action place_in_container
        :parameters (?o - item ?c - container)
        :precondition (and (visible ?o) (not (in ?o ?c)))
        :effect (and (in ?o ?c) (not (on ?o table)) (increase (total-cost) 2))
    )

    (:action remove_from_container
        :parameters (?o - item ?c - container)
        :precondition (in ?o ?c)
        :effect (and (not (in ?o ?c)) (on ?o table) (increase (total-cost) 2))
    )
)
